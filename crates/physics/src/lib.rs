//! Articulated rigid bodies (paper §2; docs/design.md §3): the dynamics, the
//! scenes a manifest describes, their controllers and contacts, the paper's
//! variables, and re-simulation of logged frames. A library: the simulate
//! stage runs scenes with it to write trajectories; the test stage
//! re-simulates logged frames with it as the simulator baseline.
//!
//! - [`spatial`], [`model`], [`dynamics`]: 6D spatial algebra, the link tree
//!   (ball hinges and one-DOF joints, couplings between them), the
//!   articulated-body algorithm (O(n); a coupled model's dynamics by the
//!   dense joint-space formulation), energy and momenta.
//! - [`joint_space`]: that formulation (the mass matrix, the bias, a
//!   coupled model's accelerations), and the efforts that hold a robot
//!   still against gravity beside its mass matrix's diagonal, which a PD
//!   loop on gravity compensation is built from.
//! - [`integrate`]: the implicit integrator (the default: semi-implicit
//!   Euler with the joints' damping, friction, limits and drives taken
//!   implicitly), semi-implicit Euler and RK4 over a reusable [`Stepper`].
//! - [`batch`]: many states at once on one thread (SIMD lanes), the
//!   articulated-body algorithm and the (implicit) semi-implicit Euler step;
//!   [`batch_scene`]: a scene's states stepped so, each under its own
//!   torques, as a planner tries candidates.
//! - [`contact`], [`controller`]: floor and arena wall; hinge torques.
//! - [`joints`]: a robot joint's effort limit, damping, friction and soft
//!   position limits.
//! - [`scene`]: a manifest scene, its kind's defaults and initial states.
//! - [`plant`]: how the plant the data come from departs from the scene.
//! - [`variables`]: the paper's variables a scene has, names and values.
//! - [`runner`]: one scene's runs, frame by frame.
//! - [`foxglove`]: a scene's motion as Foxglove messages, to watch a log.
//! - [`replay`]: re-simulating a log's frames from its scene records.
//! - [`urdf`]: robot descriptions read into a link tree.
//!
//! [`Stepper`]: integrate::Stepper

pub mod batch;
pub mod batch_scene;
pub mod contact;
pub mod controller;
pub mod dynamics;
pub mod foxglove;
pub mod integrate;
pub mod joint_space;
pub mod joints;
pub mod model;
pub mod plant;
pub mod replay;
pub mod runner;
pub mod scene;
pub mod spatial;
#[cfg(test)]
mod tests;
pub mod urdf;
pub mod variables;

pub use integrate::Integrator;
pub use runner::{
    Prepared, Runner, SceneForces, generalized_state, simulate_run, state_from_generalized,
    state_names,
};
pub use scene::{Scene, SceneKind};
