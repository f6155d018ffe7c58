//! How a stage reports progress without knowing who displays it: the CLI
//! shows a progress bar, tests and library callers pass [`Silent`].

/// A sink for progress of one long piece of work.
pub trait Progress: Sync {
    /// Announces the total amount of work, in units of `unit`.
    fn start(&self, what: &str, total: u64, unit: &str);
    /// Reports `n` more units done.
    fn advance(&self, n: u64);
}

/// Progress that goes nowhere.
pub struct Silent;

impl Progress for Silent {
    fn start(&self, _what: &str, _total: u64, _unit: &str) {}
    fn advance(&self, _n: u64) {}
}
