//! The rapier world: a kinematic end effector and a dynamic pole on a revolute impulse joint.

use rapier3d_f64::prelude::*;

use crate::params::PendulumParams;

/// Ratio of the pole's inertia about its own long axis to the transverse inertia. The
/// revolute joint locks that rotation; a small positive value keeps the mass matrix regular.
const AXIAL_INERTIA_RATIO: f64 = 1e-3;

/// Solver iterations per physics step (rapier's default is 4; more tightens the joint).
const SOLVER_ITERATIONS: usize = 8;

/// A pole hinged on a kinematic end effector that moves along the world x axis.
///
/// World frame: x horizontal (the end effector's axis), y up, hinge axis z. The pole's body
/// origin is the pivot and its centre of mass lies at `pole_com` along the body's +y axis.
/// The pole angle `theta` is measured from +y and is positive toward +x, i.e. it is the
/// negated rotation about +z.
///
/// Known rapier behaviour this design relies on: a multibody rooted on a
/// kinematic body does not feel the base acceleration, so the pole hangs on an *impulse*
/// joint; contacts are off (the bodies have no colliders anyway), sleeping is disabled, and
/// hinge damping is a force-based velocity motor with target 0, which is exact viscous
/// damping.
pub struct PoleWorld {
    world: PhysicsWorld,
    effector: RigidBodyHandle,
    pole: RigidBodyHandle,
}

impl std::fmt::Debug for PoleWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PoleWorld")
            .field("theta", &self.theta())
            .field("theta_dot", &self.theta_dot())
            .field("pivot_x", &self.pivot_x())
            .finish_non_exhaustive()
    }
}

impl PoleWorld {
    /// Builds the world with the end effector at `x = 0` at rest and the pole at angle
    /// `theta0` \[rad\] at rest. `params` must be valid.
    pub fn new(params: &PendulumParams, theta0: f64) -> Self {
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::new(0.0, -params.gravity, 0.0);
        world.integration_parameters.dt = params.physics_step();
        world.integration_parameters.num_solver_iterations = SOLVER_ITERATIONS;

        let effector = world.insert_body(
            RigidBodyBuilder::kinematic_position_based()
                .translation(Vector::ZERO)
                .can_sleep(false),
        );
        let inertia = params.pole_inertia_com;
        let mass_props = MassProperties::new(
            Vector::new(0.0, params.pole_com, 0.0),
            params.pole_mass,
            Vector::new(inertia, inertia * AXIAL_INERTIA_RATIO, inertia),
        );
        let pole = world.insert_body(
            RigidBodyBuilder::dynamic()
                .translation(Vector::ZERO)
                .rotation(Vector::new(0.0, 0.0, -theta0))
                .additional_mass_properties(mass_props)
                .linear_damping(0.0)
                .angular_damping(0.0)
                .can_sleep(false),
        );
        let mut hinge = RevoluteJointBuilder::new(Vector::Z)
            .local_anchor1(Vector::ZERO)
            .local_anchor2(Vector::ZERO)
            .contacts_enabled(false);
        if params.hinge_damping > 0.0 {
            hinge = hinge
                .motor_model(MotorModel::ForceBased)
                .motor_velocity(0.0, params.hinge_damping);
        }
        world.insert_impulse_joint(effector, pole, hinge);
        Self {
            world,
            effector,
            pole,
        }
    }

    /// Moves the end effector to `effector_x` over one physics step and integrates the pole.
    pub fn step(&mut self, effector_x: f64) {
        if let Some(body) = self.world.bodies.get_mut(self.effector) {
            body.set_next_kinematic_translation(Vector::new(effector_x, 0.0, 0.0));
        }
        self.world.step();
    }

    /// True pole angle \[rad\], positive toward +x.
    pub fn theta(&self) -> f64 {
        self.world.bodies.get(self.pole).map_or(f64::NAN, |body| {
            let up = *body.rotation() * Vector::Y;
            up.x.atan2(up.y)
        })
    }

    /// True pole angular velocity \[rad/s\], positive toward +x.
    pub fn theta_dot(&self) -> f64 {
        self.world
            .bodies
            .get(self.pole)
            .map_or(f64::NAN, |body| -body.angvel().z)
    }

    /// Position of the pole's pivot point as integrated by rapier \[m\] (x component).
    pub fn pivot_x(&self) -> f64 {
        self.world
            .bodies
            .get(self.pole)
            .map_or(f64::NAN, |body| body.translation().x)
    }
}
