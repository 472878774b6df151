//! What a query asks for besides its rays: the range of `t` that counts and the threads that
//! run it.

use std::num::NonZeroUsize;

use crate::error::Result;
use crate::input_err;

/// Which threads run a query.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Threads {
    /// rayon's global pool: every core.
    All,
    /// The calling thread only.
    One,
    /// A pool of this many threads (created once per size and kept).
    Count(NonZeroUsize),
}

impl Threads {
    pub fn from_count(n: Option<usize>) -> Result<Self> {
        match n {
            None => Ok(Self::All),
            Some(0) => input_err!("threads must be at least 1 (or None for all cores), got 0"),
            Some(1) => Ok(Self::One),
            Some(n) => Ok(Self::Count(NonZeroUsize::new(n).expect("n > 1"))),
        }
    }
}

/// The range and threads of a query. Hits count when `t_min <= t < t_max`, in units of each
/// direction's length.
#[derive(Clone, Copy, Debug)]
pub struct Query {
    pub t_min: f32,
    pub t_max: f32,
    pub threads: Threads,
    /// Count the rays as the calling call's progress (`process::counter`): set by a ray query
    /// that is itself the call, not by the algorithms that cast rays on the way to theirs.
    pub report: bool,
}

impl Query {
    pub fn new(t_min: f32, t_max: f32) -> Self {
        Self {
            t_min,
            t_max,
            threads: Threads::All,
            report: false,
        }
    }
}
