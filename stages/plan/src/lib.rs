//! The plan stage (paper §1: "based on iterated faster-than-real-time
//! prediction of what would happen given certain applied torques …, the
//! torques etc. can be changed until the predicted solution is
//! satisfactory"): model-predictive control of a scene in the true
//! simulator, with a forward model — the trained ALN, the linear baseline,
//! or the simulator itself at a coarser step — searched by a sampling
//! planner ([`planner`]).
//!
//! State of this crate: the planners; the tasks, forward models, episodes
//! and the stage's files follow.

pub mod episode;
pub mod forward;
pub mod planner;
pub mod task;
