//! One free rigid box under gravity (the `tumbler` scene): the single-link
//! case of the articulated-body dynamics, integrated about the centre of
//! mass, with the paper's variables (DESIGN.md §3) reported at the link's
//! proximal hinge — one end of the box's long (x) axis — in the link frame.
//!
//! Without contacts a free body has no external force or torque, so the
//! variable set is v, a, ω and ω̇ of link 1 (12 numbers).

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

use crate::Integrator;

/// Mass properties of the box and the gravity it falls in.
#[derive(Clone, Debug)]
pub struct Body {
    /// Mass (kg).
    pub mass: f64,
    /// Principal moments of inertia about the centre of mass (kg m²), link frame.
    pub inertia: Vector3<f64>,
    /// From the proximal hinge to the centre of mass, link frame (m).
    pub c: Vector3<f64>,
    /// Gravity in the inertial frame (m/s²).
    pub gravity: Vector3<f64>,
}

impl Body {
    /// A solid box of the given edge lengths; its hinge is the centre of the
    /// face at −x/2.
    pub fn solid_box(mass: f64, size: [f64; 3], gravity: [f64; 3]) -> Body {
        let [x, y, z] = size.map(|s| s * s);
        Body {
            mass,
            inertia: Vector3::new(y + z, x + z, x + y) * (mass / 12.0),
            c: Vector3::new(size[0] / 2.0, 0.0, 0.0),
            gravity: Vector3::from(gravity),
        }
    }

    /// ω̇ from Euler's equations for a torque-free body: J ω̇ = −ω × J ω.
    fn omega_dot(&self, omega: &Vector3<f64>) -> Vector3<f64> {
        let h = self.inertia.component_mul(omega);
        (-omega.cross(&h)).component_div(&self.inertia)
    }

    /// Inertia about the centre of mass, link frame.
    pub fn inertia_matrix(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal(&self.inertia)
    }

    /// Total energy (kinetic + potential, potential zero at the origin).
    pub fn energy(&self, s: &State) -> f64 {
        0.5 * self.mass * s.v.norm_squared()
            + 0.5 * s.omega.dot(&self.inertia.component_mul(&s.omega))
            - self.mass * self.gravity.dot(&s.p)
    }
}

/// The body's state: centre of mass position and velocity (inertial frame),
/// orientation (link → inertial) and angular velocity (link frame).
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    pub p: Vector3<f64>,
    pub q: UnitQuaternion<f64>,
    pub v: Vector3<f64>,
    pub omega: Vector3<f64>,
}

/// Names of the generalized-state components in the log, in the order of
/// [`generalized_state`].
pub const STATE_NAMES: [&str; 13] = [
    "root.p.x",
    "root.p.y",
    "root.p.z",
    "root.q.x",
    "root.q.y",
    "root.q.z",
    "root.q.w",
    "root.v.x",
    "root.v.y",
    "root.v.z",
    "root.omega.x",
    "root.omega.y",
    "root.omega.z",
];

/// Names of the learned variables, in the order of [`variables`].
pub const VARIABLE_NAMES: [&str; 12] = [
    "v.1.x",
    "v.1.y",
    "v.1.z",
    "a.1.x",
    "a.1.y",
    "a.1.z",
    "omega.1.x",
    "omega.1.y",
    "omega.1.z",
    "omega_dot.1.x",
    "omega_dot.1.y",
    "omega_dot.1.z",
];

/// The generalized state as logged: hinge position and orientation quaternion
/// (x, y, z, w) in the inertial frame, hinge velocity (inertial), ω (link).
pub fn generalized_state(body: &Body, s: &State, out: &mut [f64; 13]) {
    let c_world = s.q * body.c;
    let hinge = s.p - c_world;
    let hinge_v = s.v - (s.q * s.omega).cross(&c_world);
    let q = s.q.quaternion();
    out[..3].copy_from_slice(hinge.as_slice());
    out[3..7].copy_from_slice(&[q.i, q.j, q.k, q.w]);
    out[7..10].copy_from_slice(hinge_v.as_slice());
    out[10..].copy_from_slice(s.omega.as_slice());
}

/// The paper's variables at the hinge, all in the link frame: hinge velocity
/// v, hinge acceleration a, angular velocity ω and its rate ω̇.
pub fn variables(body: &Body, s: &State, out: &mut [f64; 12]) {
    let w = s.omega;
    let wd = body.omega_dot(&w);
    let v = s.q.inverse() * s.v - w.cross(&body.c);
    let a = s.q.inverse() * body.gravity - wd.cross(&body.c) - w.cross(&w.cross(&body.c));
    for (k, vec) in [v, a, w, wd].iter().enumerate() {
        out[3 * k..3 * k + 3].copy_from_slice(vec.as_slice());
    }
}

/// Advances `s` by `dt`.
pub fn step(body: &Body, s: &mut State, dt: f64, integrator: Integrator) {
    match integrator {
        Integrator::SemiImplicitEuler => {
            // Momenta first, then the pose with the new velocities. The
            // angular momentum lives in the inertial frame, where only a
            // torque changes it (here none: it is conserved exactly), and ω
            // follows from it and the orientation, so |ω| stays bounded.
            // The rotation uses ω at the half-step orientation: with the
            // start-of-step ω the energy of a body spinning near its
            // intermediate axis wanders by a factor of two within a minute.
            s.v += body.gravity * dt;
            let momentum = s.q * body.inertia.component_mul(&s.omega);
            s.p += s.v * dt;
            let half = s.q * UnitQuaternion::from_scaled_axis(s.omega * (dt / 2.0));
            let omega_half = (half.inverse() * momentum).component_div(&body.inertia);
            s.q *= UnitQuaternion::from_scaled_axis(omega_half * dt);
            s.q.renormalize();
            s.omega = (s.q.inverse() * momentum).component_div(&body.inertia);
        }
        Integrator::Rk4 => rk4(body, s, dt),
    }
}

/// The time derivative of the state: (ṗ, q̇, v̇, ω̇), with q̇ = ½ q ⊗ (ω, 0).
fn derivative(
    body: &Body,
    q: &Quaternion<f64>,
    v: &Vector3<f64>,
    omega: &Vector3<f64>,
) -> (Vector3<f64>, Quaternion<f64>, Vector3<f64>, Vector3<f64>) {
    let q_dot = q * Quaternion::from_imag(*omega) * 0.5;
    (*v, q_dot, body.gravity, body.omega_dot(omega))
}

fn rk4(body: &Body, s: &mut State, dt: f64) {
    let q0 = *s.q.quaternion();
    let (p0, v0, w0) = (s.p, s.v, s.omega);
    let k1 = derivative(body, &q0, &v0, &w0);
    let at = |k: &(Vector3<f64>, Quaternion<f64>, Vector3<f64>, Vector3<f64>), h: f64| {
        (p0 + k.0 * h, q0 + k.1 * h, v0 + k.2 * h, w0 + k.3 * h)
    };
    let s2 = at(&k1, dt / 2.0);
    let k2 = derivative(body, &s2.1, &s2.2, &s2.3);
    let s3 = at(&k2, dt / 2.0);
    let k3 = derivative(body, &s3.1, &s3.2, &s3.3);
    let s4 = at(&k3, dt);
    let k4 = derivative(body, &s4.1, &s4.2, &s4.3);
    let h = dt / 6.0;
    s.p = p0 + (k1.0 + k2.0 * 2.0 + k3.0 * 2.0 + k4.0) * h;
    s.q = UnitQuaternion::from_quaternion(q0 + (k1.1 + k2.1 * 2.0 + k3.1 * 2.0 + k4.1) * h);
    s.v = v0 + (k1.2 + k2.2 * 2.0 + k3.2 * 2.0 + k4.2) * h;
    s.omega = w0 + (k1.3 + k2.3 * 2.0 + k3.3 * 2.0 + k4.3) * h;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body() -> Body {
        Body::solid_box(2.0, [0.4, 0.2, 0.1], [0.0, 0.0, -9.81])
    }

    fn spinning(omega: [f64; 3]) -> State {
        State {
            p: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            v: Vector3::new(1.0, 0.0, 3.0),
            omega: Vector3::from(omega),
        }
    }

    fn run(s: &mut State, dt: f64, steps: usize, integrator: Integrator) {
        for _ in 0..steps {
            step(&body(), s, dt, integrator);
        }
    }

    #[test]
    fn box_inertia_is_textbook() {
        // I_xx = m (y² + z²) / 12 for a solid box.
        let b = body();
        assert!((b.inertia.x - 2.0 * (0.04 + 0.01) / 12.0).abs() < 1e-15);
        assert!((b.inertia.z - 2.0 * (0.16 + 0.04) / 12.0).abs() < 1e-15);
    }

    #[test]
    fn rk4_conserves_energy_and_angular_momentum() {
        let b = body();
        let mut s = spinning([0.3, 20.0, 0.5]);
        let e0 = b.energy(&s);
        let l0 = s.q * b.inertia.component_mul(&s.omega);
        run(&mut s, 1e-3, 10_000, Integrator::Rk4);
        let l1 = s.q * b.inertia.component_mul(&s.omega);
        assert!(((b.energy(&s) - e0) / e0).abs() < 1e-6, "energy drift");
        assert!((l1 - l0).norm() / l0.norm() < 1e-6, "momentum drift");
    }

    #[test]
    fn rk4_energy_drift_is_fourth_order() {
        // Rotational energy only (free fall is integrated exactly by RK4).
        let b = body();
        let drift = |dt: f64| {
            let mut s = spinning([0.3, 20.0, 0.5]);
            let e = |s: &State| s.omega.dot(&b.inertia.component_mul(&s.omega));
            let e0 = e(&s);
            run(&mut s, dt, (1.0 / dt).round() as usize, Integrator::Rk4);
            ((e(&s) - e0) / e0).abs()
        };
        let (coarse, fine) = (drift(4e-3), drift(2e-3));
        assert!(coarse / fine > 10.0, "coarse {coarse:e}, fine {fine:e}");
    }

    #[test]
    fn semi_implicit_euler_conserves_momentum_and_bounds_energy() {
        let b = body();
        let mut s = spinning([0.3, 20.0, 0.5]);
        let rotational = |s: &State| s.omega.dot(&b.inertia.component_mul(&s.omega));
        let e0 = rotational(&s);
        let l0 = s.q * b.inertia.component_mul(&s.omega);
        let mut worst: f64 = 0.0;
        for _ in 0..100 {
            run(&mut s, 1e-3, 1000, Integrator::SemiImplicitEuler);
            worst = worst.max(((rotational(&s) - e0) / e0).abs());
        }
        let l1 = s.q * b.inertia.component_mul(&s.omega);
        let drift = (l1 - l0).norm() / l0.norm();
        // Conserved up to round-off: 1e5 steps of about 1e-16 each.
        assert!(drift < 1e-10, "angular momentum drift {drift:e}");
        assert!(worst < 2e-3, "energy wandered by {worst:e} over 100 s");
    }

    #[test]
    fn free_fall_of_the_centre_of_mass_is_exact() {
        let mut s = spinning([0.0, 0.0, 0.0]);
        run(&mut s, 1e-3, 1000, Integrator::Rk4);
        // p = v0 t + g t² / 2 at t = 1.
        assert!((s.p - Vector3::new(1.0, 0.0, 3.0 - 9.81 / 2.0)).norm() < 1e-9);
    }

    #[test]
    fn spinning_fast_stays_finite_and_unit() {
        let mut s = spinning([100.0, 1.0, 0.5]);
        run(&mut s, 1e-4, 100_000, Integrator::SemiImplicitEuler);
        assert!(s.omega.iter().all(|w| w.is_finite()));
        assert!((s.q.quaternion().norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn hinge_variables_follow_rigid_body_kinematics() {
        // At rest in free fall with no spin, the hinge falls with gravity.
        let b = body();
        let s = State {
            omega: Vector3::zeros(),
            v: Vector3::zeros(),
            ..spinning([0.0; 3])
        };
        let mut out = [0.0; 12];
        variables(&b, &s, &mut out);
        assert_eq!(&out[3..6], &[0.0, 0.0, -9.81]);
        // Spinning about z at rate w: the hinge, −c from the centre of mass,
        // moves at −w × c and accelerates centripetally towards the centre.
        let s = State {
            omega: Vector3::new(0.0, 0.0, 2.0),
            v: Vector3::zeros(),
            ..spinning([0.0; 3])
        };
        let b0 = Body {
            gravity: Vector3::zeros(),
            ..b
        };
        variables(&b0, &s, &mut out);
        assert!((out[1] + 2.0 * 0.2).abs() < 1e-15, "v.1.y = {}", out[1]);
        assert!((out[3] - 4.0 * 0.2).abs() < 1e-15, "a.1.x = {}", out[3]);
    }
}
