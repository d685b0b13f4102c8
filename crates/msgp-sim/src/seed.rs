//! Deterministic derivation of independent random streams from one user seed.

/// The random streams of an episode; each gets its own generator so that, e.g., changing
/// the controller does not change the measurement noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stream {
    /// The random initial pole angle.
    InitialState,
    /// Measurement noise.
    MeasurementNoise,
    /// Random excitation signal.
    Excitation,
    /// The gains of a random-policy rollout.
    RandomGains,
    /// Stability-test start number `i` (its own episode seed); its first noise draw.
    StabilityStart(u32),
    /// Evaluation episode `episode` (below 65 536) of a learning loop's `iteration`: its own
    /// episode seed.
    Evaluation {
        /// The loop's iteration.
        iteration: u32,
        /// The evaluation episode.
        episode: u32,
    },
    /// Further noise draws of a stability-test start (`repeat ≥ 1`, below 65 536).
    StabilityRepeat {
        /// Start number.
        start: u32,
        /// Noise draw.
        repeat: u32,
    },
}

impl Stream {
    fn tag(self) -> u64 {
        match self {
            Stream::InitialState => 1,
            Stream::MeasurementNoise => 2,
            Stream::Excitation => 3,
            Stream::RandomGains => 4,
            Stream::StabilityStart(i) => 0x1000 + u64::from(i),
            Stream::Evaluation { iteration, episode } => {
                (2 << 48) + (u64::from(iteration) << 16) + u64::from(episode & 0xFFFF)
            }
            Stream::StabilityRepeat { start, repeat } => {
                (1 << 48) + (u64::from(start) << 16) + u64::from(repeat & 0xFFFF)
            }
        }
    }
}

/// Seed for `stream` derived from the user `seed` ([`msgp_core::numeric::seed::derive`]).
pub fn rng_for(seed: u64, stream: Stream) -> u64 {
    msgp_core::numeric::seed::derive(seed, stream.tag())
}
