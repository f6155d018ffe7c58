//! A robot's one-DOF joints as its description states them: the effort
//! limit clamping the controller's command, and the passive efforts —
//! viscous damping, Coulomb friction and soft position limits — added to it.
//!
//! - Damping: −b q̇, b the URDF's `damping` plus the scene's
//!   `hinge_damping`.
//! - Friction: −μ q̇ / max(|q̇|, 0.01), Coulomb above a slip speed of 0.01
//!   rad/s (or m/s) and viscous below it. Under the implicit integrator
//!   (the default) its slope is taken implicitly ([`JointLaw::slopes`]), so
//!   it is Coulomb above the slip speed whatever the link's inertia; under
//!   semi-implicit Euler its viscous coefficient is capped at I / (2 dt) (I
//!   the link's own inertia about the axis), as an explicit step cannot
//!   resolve a stiffer one.
//! - Limits: past a bound by d > 0, a spring–damper pushing back,
//!   max(0, k d + c ḋ), that never pulls; k = I (2π / (20 dt))² (a period of
//!   20 of the scene's integration steps) and c = 2 √(k I), critical
//!   damping, with I the smaller of the link's own inertia about the axis
//!   and the joint's effective inertia with the robot at rest (what a
//!   torque on it alone meets, the rest free to move: a humanoid's waist on
//!   its floating base moves 0.03 kg m², not its link's 0.38, and a spring
//!   sized on the latter threw it apart). The laws are the scene's: re-simulating
//!   its frames with coarser steps keeps them, and may not resolve them (a
//!   blow-up the test stage scores as one).
//! - Effort: the command clamped to ± the URDF's `effort` (when it gives
//!   one above 0).
//! - Velocity (a scene's `velocity_limits`): the drive holds the joint
//!   within ± the URDF's `velocity` the way ros_control's soft limits do:
//!   the effort is clamped to [−k (q̇ + v), −k (q̇ − v)] (within ± the effort
//!   limit E), so no effort speeds the joint past its limit and one beyond
//!   it is braked. Under the implicit integrator (with an effort limit to
//!   size it on; else as under semi-implicit Euler) k = E / (0.05 v): the
//!   drive gives its whole effort until within 5% of the limit, none at
//!   it, and brakes with its whole effort 5% past it, its slope k taken
//!   implicitly ([`JointLaw::drive`]). Under semi-implicit Euler k = min(E
//!   / (0.1 v), I / (2 dt)), capped as friction is: there a light link's
//!   drive gives less than its effort limit near the velocity limit, k v at
//!   rest, and a joint pushed on by the rest of the robot may pass its
//!   limit by a margin that grows as its own inertia shrinks.

use crate::urdf::JointSpec;

/// Below this joint speed (rad/s or m/s), friction is viscous.
pub const FRICTION_SLIP_SPEED: f64 = 0.01;

/// Integration steps per period of a limit's spring on the joint's
/// effective inertia.
pub const LIMIT_PERIOD_STEPS: f64 = 20.0;

/// Under the implicit integrator, the fraction of its velocity limit within
/// which a drive gives less than its whole effort (and past which it brakes
/// with all of it).
pub const DRIVE_BAND: f64 = 0.05;

/// One affine piece of a drive's effort as a function of the joint
/// velocity: `offset − slope · q̇`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DrivePiece {
    /// Which piece, in the order of rising velocity (−2 … 2).
    pub index: i8,
    pub offset: f64,
    /// −∂effort/∂q̇ (≥ 0).
    pub slope: f64,
}

impl DrivePiece {
    /// The piece's effort at velocity `qd`.
    pub fn at(&self, qd: f64) -> f64 {
        self.offset - self.slope * qd
    }
}

/// One joint's limits and passive dynamics, ready to apply.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLaw {
    /// Viscous damping b.
    pub damping: f64,
    /// Coulomb friction μ.
    pub friction: f64,
    /// The largest viscous coefficient friction may take.
    pub friction_cap: f64,
    /// Position limits, if any.
    pub range: Option<(f64, f64)>,
    /// The limit spring's stiffness k and damping c.
    pub stiffness: f64,
    pub limit_damping: f64,
    /// The effort limit (infinite when the description gives none).
    pub effort: f64,
    /// The velocity limit the drive holds (infinite when it holds none).
    pub velocity: f64,
    /// The drive's gain k against speed near and past that limit.
    pub velocity_gain: f64,
}

impl JointLaw {
    /// The law of a joint as `spec` states it, with `added_damping` and,
    /// from a plant, `added_friction`, for integration steps of `dt`; with
    /// `hold_velocity`, the drive holds the joint within the description's
    /// velocity limit, if it gives one. The limit's spring and damper are
    /// sized on the smaller of `own`, the link's own inertia about the axis,
    /// and `effective`, the joint's effective inertia
    /// ([`crate::dynamics::effective_inertias`]): sized on its link's own
    /// alone, they were too stiff for a joint whose parent moves too, and a
    /// humanoid's waist blew up at its limit. With `implicit`, steps take
    /// the passive efforts' and the drive's slopes implicitly: friction's is
    /// not capped and the drive's gain is its effort's over
    /// [`DRIVE_BAND`] of its velocity limit. Without, both are capped at
    /// `own` / (2 dt), what an explicit step resolves.
    pub fn new(
        (own, effective): (f64, f64),
        spec: &JointSpec,
        added_damping: f64,
        added_friction: Option<f64>,
        hold_velocity: bool,
        (dt, implicit): (f64, bool),
    ) -> JointLaw {
        let held = own.min(effective);
        let omega = std::f64::consts::TAU / (LIMIT_PERIOD_STEPS * dt);
        let stiffness = held * omega * omega;
        let effort = spec.effort.unwrap_or(f64::INFINITY);
        let velocity = spec
            .velocity
            .filter(|_| hold_velocity)
            .unwrap_or(f64::INFINITY);
        let explicit_cap = own / (2.0 * dt);
        let velocity_gain = match implicit && effort.is_finite() {
            true => effort / (DRIVE_BAND * velocity),
            // With no effort limit to size it on, the drive brakes as an
            // explicit step allows.
            false => (effort / (0.1 * velocity)).min(explicit_cap),
        };
        JointLaw {
            velocity,
            velocity_gain,
            damping: spec.damping + added_damping,
            friction: match added_friction {
                Some(added) => spec.friction + added,
                None => spec.friction,
            },
            friction_cap: if implicit {
                f64::INFINITY
            } else {
                explicit_cap
            },
            range: spec.range,
            stiffness,
            limit_damping: 2.0 * (stiffness * held).sqrt(),
            effort,
        }
    }

    /// The command clamped to the effort limit.
    pub fn clamp(&self, command: f64) -> f64 {
        command.clamp(-self.effort, self.effort)
    }

    /// The effort the drive gives for `effort` (already within the effort
    /// limit) at joint velocity `qd` — within the velocity limit's soft
    /// bounds, if it holds one — and how it falls as the velocity rises,
    /// −∂/∂q̇ (the gain where a bound binds between the effort limits, else
    /// zero). The simulator takes the piece ([`JointLaw::drive_piece`]);
    /// the tests read its value.
    #[cfg(test)]
    pub(crate) fn drive(&self, effort: f64, qd: f64) -> (f64, f64) {
        let piece = self.drive_piece(effort, qd);
        (piece.at(qd), piece.slope)
    }

    /// The affine piece of the drive's effort, as a function of the joint
    /// velocity, that holds at velocity `at` for the command `effort`
    /// (already within the effort limit).
    pub fn drive_piece(&self, effort: f64, at: f64) -> DrivePiece {
        self.piece(effort, self.piece_index(effort, at))
    }

    /// The piece next to `from` toward the one holding at velocity `end`
    /// (`from` itself when that holds there), for the command `effort`. An
    /// implicit step takes the piece holding at its end
    /// ([`crate::integrate::Forces::refine`]), found one piece at a time:
    /// a light link's whole effort may carry it across the band in one
    /// step, and back under the brake, while the step's end lies in the
    /// band between.
    pub fn drive_toward(&self, effort: f64, from: DrivePiece, end: f64) -> DrivePiece {
        let to = self.piece_index(effort, end);
        let step = match to.cmp(&from.index) {
            std::cmp::Ordering::Equal => return from,
            order => order as i8,
        };
        let mut next = from.index + step;
        // A slope no velocity takes for this command (the lower one for a
        // command at +E, the upper for −E) is passed over.
        while next != to
            && ((next == -1 && effort >= self.effort) || (next == 1 && effort <= -self.effort))
        {
            next += step;
        }
        self.piece(effort, next)
    }

    /// Which piece holds at velocity `x`, in the order of rising velocity:
    /// −2 the brake at +E, −1 the lower bound's slope, 0 the command, 1 the
    /// upper bound's slope, 2 the brake at −E.
    fn piece_index(&self, effort: f64, x: f64) -> i8 {
        if self.velocity.is_infinite() {
            return 0;
        }
        let k = self.velocity_gain;
        let (low, high) = (-k * (x + self.velocity), -k * (x - self.velocity));
        match () {
            () if effort > high && high > -self.effort => 1,
            () if effort > high => 2,
            () if effort < low && low < self.effort => -1,
            () if effort < low => -2,
            () => 0,
        }
    }

    /// Piece `index` (see [`JointLaw::piece_index`]) for the command `effort`.
    fn piece(&self, effort: f64, index: i8) -> DrivePiece {
        let k = self.velocity_gain;
        let (offset, slope) = match index {
            2 => (-self.effort, 0.0),
            1 => (k * self.velocity, k),
            -1 => (-k * self.velocity, k),
            -2 => (self.effort, 0.0),
            _ => (effort, 0.0),
        };
        DrivePiece {
            index,
            offset,
            slope,
        }
    }

    /// The passive effort at position `q` and velocity `qd`: damping,
    /// friction and the limits' springs.
    pub fn passive(&self, q: f64, qd: f64) -> f64 {
        let viscous = (self.friction / qd.abs().max(FRICTION_SLIP_SPEED)).min(self.friction_cap);
        let effort = -(self.damping + viscous) * qd;
        match self.limit_effort(q, qd) {
            Some(push) => effort + push,
            None => effort,
        }
    }

    /// Past a bound, what the limit's spring–damper gives at (`q`, `qd`):
    /// a push back, or zero where it would pull; `None` within the range.
    fn limit_effort(&self, q: f64, qd: f64) -> Option<f64> {
        match self.range? {
            (_, high) if q > high => {
                Some(-(self.stiffness * (q - high) + self.limit_damping * qd).max(0.0))
            }
            (low, _) if q < low => {
                Some((self.stiffness * (low - q) - self.limit_damping * qd).max(0.0))
            }
            _ => None,
        }
    }

    /// How [`JointLaw::passive`] falls as the velocity and as the position
    /// rise at (`q`, `qd`): (b, k) = (−∂/∂q̇, −∂/∂q), each ≥ 0 — damping,
    /// friction's viscous slope below its slip speed (or its cap) and an
    /// engaged limit's damper and spring.
    pub fn slopes(&self, q: f64, qd: f64) -> (f64, f64) {
        let coefficient = self.friction / qd.abs().max(FRICTION_SLIP_SPEED);
        let friction = if coefficient >= self.friction_cap {
            self.friction_cap
        } else if qd.abs() < FRICTION_SLIP_SPEED {
            coefficient
        } else {
            0.0
        };
        // Engaged: past a bound and pushing.
        match self.limit_effort(q, qd).is_some_and(|push| push != 0.0) {
            true => (self.damping + friction + self.limit_damping, self.stiffness),
            false => (self.damping + friction, 0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The effective inertia of the joints below: a 2 kg link turning
    /// about z, 0.6 kg m² about its hinge, on a fixed base.
    const INERTIA: f64 = 0.6;

    fn law(range: Option<(f64, f64)>) -> JointLaw {
        let spec = JointSpec {
            range,
            effort: Some(10.0),
            velocity: None,
            damping: 0.5,
            friction: 0.2,
        };
        JointLaw::new((INERTIA, INERTIA), &spec, 0.25, None, false, (1e-3, false))
    }

    fn driven(hold: bool, implicit: bool, own: f64) -> JointLaw {
        let spec = JointSpec {
            range: None,
            effort: Some(10.0),
            velocity: Some(2.0),
            damping: 0.0,
            friction: 0.0,
        };
        JointLaw::new((own, own), &spec, 0.0, None, hold, (1e-3, implicit))
    }

    #[test]
    fn a_drive_holding_its_velocity_limit_gives_no_effort_past_it_and_brakes() {
        let applied = |law: &JointLaw, effort, qd| law.drive(effort, qd).0;
        let free = driven(false, false, INERTIA);
        assert_eq!(
            free.drive(10.0, 5.0),
            (10.0, 0.0),
            "not held: the command as it is"
        );
        let law = driven(true, false, INERTIA);
        // k = min(10 / 0.2, 0.6 / 2e-3) = 50.
        assert_eq!(law.velocity_gain, 50.0);
        assert_eq!(
            law.drive(10.0, 0.0),
            (10.0, 0.0),
            "far from the limit: the whole effort"
        );
        assert_eq!(applied(&law, -10.0, 0.0), -10.0);
        let (near, slope) = law.drive(10.0, 1.9);
        assert!((near - 5.0).abs() < 1e-12, "within a tenth: less");
        assert_eq!(slope, 50.0, "falling with the speed");
        assert_eq!(
            law.drive(10.0, 2.0),
            (0.0, 50.0),
            "at the limit: none onward"
        );
        assert!(
            (applied(&law, 10.0, 2.1) + 5.0).abs() < 1e-12,
            "past it: braked"
        );
        assert_eq!(
            law.drive(-10.0, 2.1),
            (-10.0, 0.0),
            "braking more is allowed"
        );
        assert_eq!(
            law.drive(10.0, 3.0),
            (-10.0, 0.0),
            "the brake within the effort limit"
        );
        assert!(
            (applied(&law, -10.0, -1.9) + 5.0).abs() < 1e-12,
            "and the same the other way"
        );
    }

    /// Under semi-implicit Euler a light link's drive is capped at what an
    /// explicit step resolves (k v at rest, less than its effort limit);
    /// under the implicit integrator it gives its whole effort until within
    /// 5% of the velocity limit, whatever the link's inertia.
    /// Toward the piece at a step's end, one piece at a time, passing over
    /// a slope the command never meets: a command at +E goes from the
    /// brake at +E (far below −v) straight to the command.
    #[test]
    fn a_step_moves_toward_the_piece_at_its_end_one_piece_at_a_time() {
        let law = driven(true, true, INERTIA);
        let at = |effort: f64, qd: f64| law.drive_piece(effort, qd).index;
        // k = 100: the lower bound is 5 at −2.05, the upper 2 at 1.98.
        assert_eq!((at(3.0, -3.0), at(3.0, -2.05), at(3.0, 0.0)), (-2, -1, 0));
        assert_eq!((at(3.0, 1.98), at(3.0, 3.0)), (1, 2));
        let from = law.drive_piece(3.0, 0.0);
        assert_eq!(law.drive_toward(3.0, from, 3.0).index, 1, "one piece on");
        assert_eq!(law.drive_toward(3.0, from, 0.5), from, "where it holds");
        let braked = law.drive_piece(10.0, -3.0);
        assert_eq!(braked.index, -2);
        assert_eq!(
            law.drive_toward(10.0, braked, 0.0).index,
            0,
            "no lower slope for a command at +E"
        );
    }

    #[test]
    fn an_implicit_drive_gives_its_effort_whatever_the_links_inertia() {
        let light = 1e-3;
        let capped = driven(true, false, light);
        // k = 1e-3 / 2e-3 = 0.5: 1 N m at rest against 10.
        assert_eq!(capped.velocity_gain, 0.5);
        assert_eq!(capped.drive(10.0, 0.0).0, 1.0);
        let law = driven(true, true, light);
        assert_eq!(law.velocity_gain, 10.0 / (DRIVE_BAND * 2.0));
        assert_eq!(law.drive(10.0, 0.0), (10.0, 0.0));
        assert_eq!(law.drive(10.0, 1.9), (10.0, 0.0), "5% short of the limit");
        let (near, slope) = law.drive(10.0, 1.95);
        assert!(
            (near - 5.0).abs() < 1e-9 && slope == 100.0,
            "{near} {slope}"
        );
        assert_eq!(law.drive(10.0, 2.0), (0.0, 100.0), "none at the limit");
        assert_eq!(law.drive(10.0, 2.1), (-10.0, 0.0), "5% past it: all of it");
        for qd in [-2.2, -2.04, -1.97, 0.0, 1.96, 1.99, 2.03] {
            let e = 1e-7;
            let by_qd = -(law.drive(3.0, qd + e).0 - law.drive(3.0, qd - e).0) / (2.0 * e);
            assert!((law.drive(3.0, qd).1 - by_qd).abs() < 1e-5, "{qd}: {by_qd}");
        }
    }

    #[test]
    fn damping_friction_and_effort_as_stated() {
        let law = law(None);
        // I about z through the hinge: 0.1 + 2 · 0.5² = 0.6.
        assert!((law.friction_cap - 0.6 / 2e-3).abs() < 1e-9);
        assert_eq!(law.clamp(25.0), 10.0);
        assert_eq!(law.clamp(-3.0), -3.0);
        // Fast: Coulomb 0.2 against the motion, plus 0.75 · q̇.
        assert!((law.passive(0.0, 2.0) - (-0.75 * 2.0 - 0.2)).abs() < 1e-12);
        // Slow: viscous 0.2 / 0.01 below the slip speed.
        assert!((law.passive(0.0, 0.005) - (-(0.75 + 20.0) * 0.005)).abs() < 1e-12);
        assert_eq!(law.passive(0.0, 0.0), 0.0);
    }

    #[test]
    fn slopes_are_the_passive_efforts_derivatives() {
        let law = law(Some((-1.0, 1.0)));
        // Fast and slow, free and past either bound, pushed and leaving.
        for (q, qd) in [
            (0.0, 2.0),
            (0.0, -0.004),
            (1.01, 0.3),
            (1.01, -0.3),
            (1.001, -5.0),
            (-1.02, 0.002),
            (-1.02, 3.0),
        ] {
            let (b, k) = law.slopes(q, qd);
            let e = 1e-7;
            let by_qd = -(law.passive(q, qd + e) - law.passive(q, qd - e)) / (2.0 * e);
            let by_q = -(law.passive(q + e, qd) - law.passive(q - e, qd)) / (2.0 * e);
            let scale = 1.0 + law.stiffness;
            assert!(
                (b - by_qd).abs() < 1e-5 * scale,
                "b at ({q}, {qd}): {b} against {by_qd}"
            );
            assert!(
                (k - by_q).abs() < 1e-5 * scale,
                "k at ({q}, {qd}): {k} against {by_q}"
            );
            assert!(b >= 0.0 && k >= 0.0);
        }
    }

    #[test]
    fn limits_push_back_and_never_pull() {
        let law = law(Some((-1.0, 1.0)));
        let free = law.passive(0.5, 0.0);
        assert_eq!(free, 0.0);
        // Past the upper bound at rest: −k d.
        let pushed = law.passive(1.01, 0.0);
        assert!((pushed + law.stiffness * 0.01).abs() < 1e-9 * law.stiffness);
        // Leaving the bound fast: the damper would pull, so nothing (but
        // damping and friction).
        let leaving = law.passive(1.001, -5.0);
        assert!((leaving - law.passive(0.0, -5.0)).abs() < 1e-12);
        // Past the lower bound: pushed up.
        assert!(law.passive(-1.02, 0.0) > 0.0);
        // k: a period of 20 steps of 1 ms on I = 0.6.
        let period = std::f64::consts::TAU * (0.6 / law.stiffness).sqrt();
        assert!((period - 0.02).abs() < 1e-12);
    }
}
