//! How many threads a call runs on: rayon's global pool by default, or a
//! pool of the asked size, built once per size and kept.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use pyo3::PyResult;

use crate::invalid;

/// Runs `work` on `threads` threads (all of rayon's by default).
pub fn run<T: Send>(threads: Option<usize>, work: impl FnOnce() -> T + Send) -> PyResult<T> {
    let Some(n) = threads else {
        return Ok(work());
    };
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<rayon::ThreadPool>>>> = OnceLock::new();
    let pool = {
        let mut pools = POOLS
            .get_or_init(Default::default)
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        match pools.get(&n) {
            Some(pool) => Arc::clone(pool),
            None => {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| invalid(format!("threads: cannot start {n} threads: {e}")))?;
                Arc::clone(pools.entry(n).or_insert(Arc::new(pool)))
            }
        }
    };
    Ok(pool.install(work))
}

/// How many rows each parallel task takes on `threads` threads (all of
/// rayon's by default): whole blocks of the batched predictor (32 rows),
/// a task for every thread.
pub fn chunk_rows(rows: usize, threads: Option<usize>) -> usize {
    let threads = threads.unwrap_or_else(rayon::current_num_threads).max(1);
    rows.div_ceil(threads).div_ceil(32).max(1) * 32
}
