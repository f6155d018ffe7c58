//! The planner's own data (issue 43; DAgger for models, Ross & Bagnell
//! 2012): every frame the ALN's planner executed, as a pair — the frame
//! before, with the controls executed, and the frame after — in
//! `pairs.parquet`'s layout (`transitions.parquet`), and beside it what the
//! scene as written predicts for the same frame under the same controls, as
//! the nominal stage does for the logged pairs
//! (`transitions-nominal.parquet`). A next round trains on them too.
//!
//! Each episode is a run of its own (numbered in the order recorded), each
//! frame but the last a step (the last has no torques after it, so no
//! frame as the log records it); every pair is a training pair. A frame the nominal
//! simulator cannot step (it blew up) is left out, as the nominal stage
//! would refuse it.

use std::path::Path;

use alnlab_common::state_log::StateFrame;
use alnlab_common::{Error, Provenance, Result};
use alnlab_physics::dynamics::State;
use alnlab_physics::{Prepared, Runner, state_from_generalized};
use alnlab_tables::pairs::{self, Key, Side, Split};
use nalgebra::Vector3;

use crate::controls::Controls;

/// File name of the planner's pairs.
pub const FILE: &str = "transitions.parquet";
/// File name of the nominal simulator's predictions of them.
pub const NOMINAL_FILE: &str = "transitions-nominal.parquet";

/// The pairs recorded so far.
pub struct Transitions<'a> {
    nominal: &'a Prepared,
    controls: Controls,
    /// Per control component, its variable's index in the scene's layout.
    control_variables: Vec<Option<usize>>,
    runner: Runner<'a>,
    torques: Vec<Vector3<f64>>,
    frame: StateFrame,
    keys: Vec<Key>,
    /// Per pair, the scene's variables before, after and as the nominal
    /// simulator predicts after.
    x: Vec<Vec<f64>>,
    y: Vec<Vec<f64>>,
    predicted: Vec<Vec<f64>>,
    runs: u32,
}

impl<'a> Transitions<'a> {
    /// Records pairs of the scene whose nominal model is `nominal`, set
    /// by `controls`.
    pub fn new(nominal: &'a Prepared, controls: &Controls) -> Transitions<'a> {
        let names = &nominal.layout.variables;
        Transitions {
            nominal,
            control_variables: controls
                .names()
                .iter()
                .map(|c| names.iter().position(|n| n == c))
                .collect(),
            controls: controls.clone(),
            runner: Runner::new(nominal, 0, 0, 0),
            torques: vec![Vector3::zeros(); nominal.model.len() - 1],
            frame: StateFrame::default(),
            keys: Vec::new(),
            x: Vec::new(),
            y: Vec::new(),
            predicted: Vec::new(),
            runs: 0,
        }
    }

    /// Starts the next episode: its pairs are a run of their own.
    pub fn start_episode(&mut self) {
        self.runs += 1;
    }

    /// Records the pair of frame `step` (`before`, as logged: under the
    /// controls `executed` from it) and the next (`after`, under the
    /// controls `next` executed from it); the nominal simulator's prediction
    /// of `after` is stepped under `executed` and seen under `next`, as
    /// the nominal stage sees a logged pair.
    pub fn record(
        &mut self,
        step: u32,
        before: &StateFrame,
        after: &StateFrame,
        executed: &[f64],
        next: &[f64],
    ) -> Result<()> {
        let p = self.nominal;
        let mut state: State =
            state_from_generalized(&p.model, &before.state).ok_or_else(|| {
                Error::Invalid(format!(
                    "scene `{}`: a planned frame's state does not fit its nominal model",
                    p.scene.name
                ))
            })?;
        self.controls.set(executed, &mut self.torques);
        self.runner.restart();
        self.runner.drive(Some(&self.torques));
        let steps = p.scene.nominal_steps_per_frame();
        let dt = p.scene.step_dt(steps);
        if self.runner.advance(&mut state, 0, steps, dt).is_err() {
            return Ok(());
        }
        self.controls.set(next, &mut self.torques);
        self.runner.drive(Some(&self.torques));
        self.runner.observe(&state, 0.0, &mut self.frame);
        let mut x = before.variables.clone();
        for (&v, &value) in self.control_variables.iter().zip(executed) {
            if let Some(v) = v {
                x[v] = value;
            }
        }
        self.keys.push(Key {
            scene: p.scene.name.clone(),
            run: self.runs - 1,
            step,
            split: Split::Train,
        });
        self.x.push(x);
        self.y.push(after.variables.clone());
        self.predicted.push(self.frame.variables.clone());
        Ok(())
    }

    /// Writes both tables into `dir`.
    pub fn write(&self, dir: &Path, provenance: &Provenance) -> Result<()> {
        let variables: Vec<&str> = self
            .nominal
            .layout
            .variables
            .iter()
            .map(String::as_str)
            .collect();
        for (file, next) in [(FILE, &self.y), (NOMINAL_FILE, &self.predicted)] {
            pairs::write(
                &dir.join(file),
                &self.keys,
                &variables,
                |side, k, r| {
                    Some(match side {
                        Side::Current => self.x[r][k],
                        Side::Next => next[r][k],
                    })
                },
                provenance,
            )?;
        }
        Ok(())
    }
}

/// Writes both tables into `dir` with no pair: a stage that planned nothing.
pub fn write_none(dir: &Path, provenance: &Provenance) -> Result<()> {
    for file in [FILE, NOMINAL_FILE] {
        pairs::write(&dir.join(file), &[], &[], |_, _, _| None, provenance)?;
    }
    Ok(())
}
