//! The run's 3D scene for Foxglove: where the end effector and the pole are at each step, and
//! what they look like, in Foxglove's well-known schemas (protobuf encoding, the schemas from
//! the `foxglove` crate), so that a run log opened in Foxglove's 3D panel shows the pole move.
//!
//! Frames (Foxglove's convention: z up; the simulator's vertical axis is its z):
//! - `world`: fixed; the end effector moves along its x axis;
//! - `end_effector`: child of `world`, translated by the true position `x`;
//! - `pole`: child of `end_effector` at the pivot, rotated by the true angle `theta` about the
//!   world's y axis, so that its z axis runs along the pole (`theta > 0` leans toward +x).
//!
//! The scene (sent once, at the first step, and kept for the whole log) holds the rail the end
//! effector may use (`±stop_x`), the end effector (a cube), the pole (a cylinder of its length)
//! and its centre of mass (a sphere). The transforms use the true, latent state: the scene
//! shows what happened, the measurement topics what the controller saw.

use foxglove::messages::{
    Color, CubePrimitive, CylinderPrimitive, FrameTransform, FrameTransforms, LinePrimitive,
    Point3, Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
};

use crate::params::PendulumParams;
use crate::plant::LatentState;

/// Topic of the frame transforms (`foxglove.FrameTransforms`).
pub const TOPIC_TRANSFORMS: &str = "/pendulum/tf";
/// Topic of the scene geometry (`foxglove.SceneUpdate`).
pub const TOPIC_SCENE: &str = "/pendulum/scene";
/// The fixed frame.
pub const FRAME_WORLD: &str = "world";
/// The end effector's frame.
pub const FRAME_END_EFFECTOR: &str = "end_effector";
/// The pole's frame (origin at the pivot, z along the pole).
pub const FRAME_POLE: &str = "pole";

/// A time in seconds (non-negative, as episode times are) as a Foxglove timestamp.
fn stamp(t: f64) -> Timestamp {
    let ns = (t.max(0.0) * 1e9).round() as u64;
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

fn vector(x: f64, y: f64, z: f64) -> Vector3 {
    Vector3 { x, y, z }
}

fn identity() -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    }
}

fn pose_at(x: f64, y: f64, z: f64) -> Pose {
    Pose {
        position: Some(vector(x, y, z)),
        orientation: Some(identity()),
    }
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// The transforms of step time `t` for the true state `latent`.
pub fn transforms(t: f64, latent: &LatentState) -> FrameTransforms {
    let half = 0.5 * latent.theta;
    FrameTransforms {
        transforms: vec![
            FrameTransform {
                timestamp: Some(stamp(t)),
                parent_frame_id: FRAME_WORLD.into(),
                child_frame_id: FRAME_END_EFFECTOR.into(),
                translation: Some(vector(latent.x, 0.0, 0.0)),
                rotation: Some(identity()),
            },
            FrameTransform {
                timestamp: Some(stamp(t)),
                parent_frame_id: FRAME_END_EFFECTOR.into(),
                child_frame_id: FRAME_POLE.into(),
                translation: Some(vector(0.0, 0.0, 0.0)),
                // rotation by theta about +y turns +z toward +x
                rotation: Some(Quaternion {
                    x: 0.0,
                    y: half.sin(),
                    z: 0.0,
                    w: half.cos(),
                }),
            },
        ],
    }
}

/// The scene's geometry for a plant with `params`, stamped `t`.
pub fn scene(params: &PendulumParams, t: f64) -> SceneUpdate {
    let entity = |id: &str, frame: &str| SceneEntity {
        timestamp: Some(stamp(t)),
        frame_id: frame.into(),
        id: id.into(),
        frame_locked: true,
        ..SceneEntity::default()
    };
    let length = params.pole_length;
    let radius = (0.02 * length).max(0.005);
    let rail = LinePrimitive {
        r#type: 0, // line strip
        pose: Some(pose_at(0.0, 0.0, 0.0)),
        thickness: 0.01,
        scale_invariant: false,
        points: [-params.stop_x, params.stop_x]
            .iter()
            .map(|&x| Point3 { x, y: 0.0, z: 0.0 })
            .collect(),
        color: Some(color(0.5, 0.5, 0.5, 1.0)),
        ..LinePrimitive::default()
    };
    let effector = CubePrimitive {
        pose: Some(pose_at(0.0, 0.0, 0.0)),
        size: Some(vector(0.08, 0.08, 0.04)),
        color: Some(color(0.2, 0.4, 0.8, 1.0)),
    };
    let pole = CylinderPrimitive {
        pose: Some(pose_at(0.0, 0.0, 0.5 * length)),
        size: Some(vector(2.0 * radius, 2.0 * radius, length)),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color: Some(color(0.9, 0.5, 0.1, 1.0)),
    };
    let com = SpherePrimitive {
        pose: Some(pose_at(0.0, 0.0, params.pole_com)),
        size: Some(vector(4.0 * radius, 4.0 * radius, 4.0 * radius)),
        color: Some(color(0.1, 0.1, 0.1, 1.0)),
    };
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![
            SceneEntity {
                lines: vec![rail],
                ..entity("rail", FRAME_WORLD)
            },
            SceneEntity {
                cubes: vec![effector],
                ..entity("end_effector", FRAME_END_EFFECTOR)
            },
            SceneEntity {
                cylinders: vec![pole],
                spheres: vec![com],
                ..entity("pole", FRAME_POLE)
            },
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pole's tip in world coordinates from the transforms, by rotating (0, 0, L) with the
    /// quaternion written out: must equal the simulator's geometry (x + L sinθ, 0, L cosθ).
    #[test]
    fn transforms_put_the_pole_tip_where_the_state_says() {
        let latent = LatentState {
            theta: 0.3,
            theta_dot: 0.0,
            x: -0.2,
            x_dot: 0.0,
            lag_acceleration: 0.0,
            delayed_command: 0.0,
        };
        let tf = transforms(1.25, &latent);
        let [ee, pole] = tf.transforms.as_slice() else {
            panic!("two transforms");
        };
        assert_eq!(
            (ee.parent_frame_id.as_str(), ee.child_frame_id.as_str()),
            ("world", "end_effector")
        );
        assert_eq!(pole.parent_frame_id, "end_effector");
        let q = pole.rotation.expect("rotation");
        let length = 0.9;
        // v' = v + 2w (q × v) + 2 q × (q × v), v = (0, 0, L), q = (0, qy, 0)
        let (qy, w) = (q.y, q.w);
        let c1 = (qy * length, 0.0, 0.0); // q × v
        let c2 = (0.0, 0.0, -qy * qy * length); // q × (q × v)
        let tip = (
            ee.translation.expect("t").x + 2.0 * w * c1.0 + 2.0 * c2.0,
            0.0,
            length + 2.0 * c2.2,
        );
        assert!(
            (tip.0 - (-0.2 + length * 0.3f64.sin())).abs() < 1e-12,
            "{tip:?}"
        );
        assert!((tip.2 - length * 0.3f64.cos()).abs() < 1e-12, "{tip:?}");
        let ts = pole.timestamp.expect("stamp");
        assert_eq!((ts.sec(), ts.nsec()), (1, 250_000_000));
    }

    #[test]
    fn the_scene_has_the_pole_of_the_parameters() {
        let params = PendulumParams::default();
        let s = scene(&params, 0.0);
        let ids: Vec<&str> = s.entities.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids, ["rail", "end_effector", "pole"]);
        let pole = &s.entities[2].cylinders[0];
        assert_eq!(pole.size.expect("size").z, params.pole_length);
        assert_eq!(
            s.entities[2].spheres[0]
                .pose
                .expect("pose")
                .position
                .expect("p")
                .z,
            params.pole_com
        );
    }
}
