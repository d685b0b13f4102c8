"""msgp: Gaussian-process dynamics models optimised for long-term predictions (MSGP)."""

from ._msgp import __version__, fit_synthetic, synthetic_system

__all__ = ["__version__", "fit_synthetic", "synthetic_system"]
