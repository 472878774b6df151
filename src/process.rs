//! Process-wide state that has to survive what Python does to a process:
//!
//! - the rayon pools every parallel step runs in. A child forked after the parent used them
//!   (`multiprocessing`'s "fork" start method) inherits the pools but not their threads, so
//!   each pool is tagged with the process id that made it and a forked child makes its own;
//! - the interruption flag that long loops poll, so Ctrl-C ends a call within a fraction of a
//!   second ([`interruptible`], [`check`]);
//! - the progress of a long call, counted by its loops in real units ([`add_total`],
//!   [`advance`]) and read by the calling thread, which draws the bar.

use std::cell::RefCell;
use std::num::NonZeroUsize;
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};

/// This process's pools, by thread count.
struct Pools {
    pid: u32,
    pools: Vec<(usize, Arc<rayon::ThreadPool>)>,
}

static POOLS: Mutex<Option<Pools>> = Mutex::new(None);

/// The number of threads `None` stands for: one per core.
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, NonZeroUsize::get)
}

/// This process's pool of `n` threads (`None`: one per core), made on first use.
pub fn pool(n: Option<usize>) -> Result<Arc<rayon::ThreadPool>> {
    let n = n.unwrap_or_else(cores).max(1);
    let pid = std::process::id();
    let mut guard = POOLS.lock().unwrap_or_else(|e| e.into_inner());
    if guard.as_ref().is_some_and(|p| p.pid != pid) {
        // Forked: the threads of these pools stayed in the parent. Dropping the pools would
        // wake threads that do not exist here; leak them instead (a few KB, once per fork).
        std::mem::forget(guard.take());
    }
    let pools = guard.get_or_insert_with(|| Pools {
        pid,
        pools: Vec::new(),
    });
    if let Some((_, p)) = pools.pools.iter().find(|(m, _)| *m == n) {
        return Ok(p.clone());
    }
    let p = rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .thread_name(|i| format!("scenesample-{i}"))
        .build()
        .map_err(|e| Error::System(format!("could not start {n} worker threads: {e}")))?;
    let p = Arc::new(p);
    pools.pools.push((n, p.clone()));
    Ok(p)
}

/// Run `f` inside this process's pool of `n` threads (`None`: one per core), so every rayon
/// parallel step of `f` runs on it and never on rayon's global pool, which a fork breaks.
pub fn install<R: Send>(n: Option<usize>, f: impl FnOnce() -> R + Send) -> Result<R> {
    Ok(pool(n)?.install(f))
}

/// Units of work done and to do, counted by a call's loops and read by its caller.
#[derive(Debug, Default)]
pub struct Progress {
    pub done: AtomicU64,
    pub total: AtomicU64,
}

impl Progress {
    /// `n` more units to do.
    pub fn add_total(&self, n: u64) {
        self.total.fetch_add(n, Ordering::Relaxed);
    }

    /// `n` more units done.
    pub fn advance(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
    }

    /// `(done, total)` now.
    pub fn now(&self) -> (u64, u64) {
        (
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        )
    }
}

thread_local! {
    /// The progress of the call whose work runs on this thread, if it keeps one.
    static COUNTING: RefCell<Option<Arc<Progress>>> = const { RefCell::new(None) };
}

/// The progress of the call whose work runs on this thread, if it keeps one: a parallel loop
/// takes it on the work's thread and counts into it from its workers.
pub fn counter() -> Option<Arc<Progress>> {
    COUNTING.with(|c| c.borrow().clone())
}

/// Count `n` more units of work for the current call (a no-op when nobody watches).
pub fn add_total(n: u64) {
    if let Some(p) = counter() {
        p.add_total(n);
    }
}

/// Count `n` units of the current call's work as done. Call it from the thread that runs the
/// call's work (its outer loop); parallel workers count into [`counter`] instead.
pub fn advance(n: u64) {
    if let Some(p) = counter() {
        p.advance(n);
    }
}

/// Run `f` with `progress` counting what it reports on this thread.
fn counting<R>(progress: Option<&Arc<Progress>>, f: impl FnOnce() -> R) -> R {
    let outer = COUNTING.with(|c| c.replace(progress.cloned()));
    let r = f();
    COUNTING.with(|c| *c.borrow_mut() = outer);
    r
}

/// Whose turn it is to run a call on the pools: 0 when free, else the holder's process id << 32
/// | 1. One call at a time: two calls sharing a pool deadlock when a worker, waiting inside one
/// call's parallel step, steals the other call's whole job and blocks in it on a lock (the GPU's)
/// the first call holds. The pool already uses every core, so taking turns costs nothing.
static TURN: AtomicU64 = AtomicU64::new(0);

/// This call's turn ([`take_turn`]); given back when dropped, even if the work panics.
struct Turn;

impl Drop for Turn {
    fn drop(&mut self) {
        TURN.store(0, Ordering::Release);
    }
}

/// Wait for this process's turn, calling `poll` every [`POLL`] meanwhile (so Ctrl-C still
/// interrupts a call that waits). A turn held in the parent before a fork is free in the child.
fn take_turn<E>(
    poll: &mut impl FnMut() -> std::result::Result<(), E>,
) -> std::result::Result<Turn, E> {
    let pid = std::process::id();
    let mine = (u64::from(pid) << 32) | 1;
    let mut last = Instant::now();
    loop {
        let now = TURN.load(Ordering::Acquire);
        let free = now == 0 || (now >> 32) as u32 != pid;
        if free
            && TURN
                .compare_exchange(now, mine, Ordering::AcqRel, Ordering::Acquire)
                .is_ok()
        {
            return Ok(Turn);
        }
        std::thread::sleep(Duration::from_millis(1));
        if last.elapsed() >= POLL {
            last = Instant::now();
            poll()?;
        }
    }
}

/// Calls being interrupted now. Long loops stop while it is nonzero ([`check`]).
static INTERRUPTING: AtomicUsize = AtomicUsize::new(0);

/// The poll of a call running on its caller's thread ([`interruptible_here`]), and when it
/// last ran.
struct Poller {
    last: Instant,
    /// True when the call is to stop.
    poll: Box<dyn FnMut() -> bool>,
}

thread_local! {
    static POLLER: RefCell<Option<Poller>> = const { RefCell::new(None) };
}

/// `Err(Error::Interrupted)` while a call is being interrupted. Loops that can run for longer
/// than about a second call this every few milliseconds of work, and pass the error up. On
/// the thread of an [`interruptible_here`] call it also runs that call's poll, every [`POLL`].
#[inline]
pub fn check() -> Result<()> {
    if INTERRUPTING.load(Ordering::Relaxed) != 0 {
        return Err(Error::Interrupted);
    }
    let stop = POLLER.with(|p| match p.borrow_mut().as_mut() {
        Some(p) if p.last.elapsed() >= POLL => {
            p.last = Instant::now();
            (p.poll)()
        }
        _ => false,
    });
    if stop {
        Err(Error::Interrupted)
    } else {
        Ok(())
    }
}

/// How often the calling thread polls for an interruption while the work runs.
pub const POLL: Duration = Duration::from_millis(20);

/// Run `work` on this process's pool while the calling thread calls `poll` every [`POLL`]. Calls
/// from several threads take turns ([`TURN`]).
/// When `poll` fails, the loops of `work` see [`check`] fail; this waits for `work` to stop
/// and returns `poll`'s error. A `work` stopped by another call's interruption (calls from
/// several threads share the flag) runs again once that one has ended, so only the call that
/// was interrupted fails. `work` must be free of side effects that a rerun would repeat.
pub fn interruptible<T: Send, E>(
    work: impl Fn() -> Result<T> + Sync,
    mut poll: impl FnMut() -> std::result::Result<(), E>,
    progress: Option<&Arc<Progress>>,
) -> std::result::Result<Result<T>, E> {
    let pool = match pool(None) {
        Ok(p) => p,
        Err(e) => return Ok(Err(e)),
    };
    let home = std::thread::current();
    let _turn = take_turn(&mut poll)?;
    loop {
        let done = AtomicBool::new(false);
        let mut out = None;
        let mut stopped = None;
        {
            let (slot, done, home, work) = (&mut out, &done, &home, &work);
            pool.in_place_scope(|s| {
                s.spawn(move |_| {
                    // Set even if `work` panics (rayon re-raises the panic when the scope
                    // ends), so the loop below never waits for a job that is gone.
                    let _finished = Finished(done, home);
                    *slot = Some(counting(progress, work));
                });
                while !done.load(Ordering::Acquire) {
                    std::thread::park_timeout(POLL);
                    if stopped.is_none() && !done.load(Ordering::Acquire) {
                        if let Err(e) = poll() {
                            INTERRUPTING.fetch_add(1, Ordering::SeqCst);
                            stopped = Some(e);
                        }
                    }
                }
            });
        }
        if let Some(e) = stopped {
            INTERRUPTING.fetch_sub(1, Ordering::SeqCst);
            return Err(e);
        }
        match out {
            // Another call's interruption stopped this one: wait for it to end, rerun.
            Some(Err(Error::Interrupted)) => wait_for_interruptions(),
            Some(r) => return Ok(r),
            None => {
                return Ok(Err(Error::System(
                    "the worker ended without a result".into(),
                )))
            }
        }
    }
}

/// Wait until no call is being interrupted (a call stopped by another's interruption reruns
/// after it).
fn wait_for_interruptions() {
    while INTERRUPTING.load(Ordering::SeqCst) != 0 {
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Marks a job finished and wakes the thread waiting for it, when dropped.
struct Finished<'a>(&'a AtomicBool, &'a std::thread::Thread);

impl Drop for Finished<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
        self.1.unpark();
    }
}

/// [`interruptible`] for single-threaded work that must stay on the calling thread: `work`
/// runs here, and its loops' [`check`] calls `poll` every [`POLL`]. Only this call stops: if
/// another call's interruption stops it, it runs again.
pub fn interruptible_here<T, E: 'static>(
    work: impl Fn() -> Result<T>,
    mut poll: impl FnMut() -> std::result::Result<(), E> + 'static,
    progress: Option<&Arc<Progress>>,
) -> std::result::Result<Result<T>, E> {
    let stopped: Rc<RefCell<Option<E>>> = Rc::new(RefCell::new(None));
    let slot = stopped.clone();
    let mine = Poller {
        last: Instant::now(),
        poll: Box::new(move || match poll() {
            Ok(()) => false,
            Err(e) => {
                *slot.borrow_mut() = Some(e);
                true
            }
        }),
    };
    // A call nested in another's work (none today) keeps the outer poll once it returns.
    let outer = POLLER.with(|p| p.borrow_mut().replace(mine));
    let r = loop {
        let r = counting(progress, &work);
        if matches!(r, Err(Error::Interrupted)) && stopped.borrow().is_none() {
            // Another call's interruption: wait for it to end, then run again.
            wait_for_interruptions();
            continue;
        }
        break r;
    };
    POLLER.with(|p| *p.borrow_mut() = outer);
    let e = stopped.borrow_mut().take();
    match e {
        Some(e) => Err(e),
        None => Ok(r),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Interruption itself is tested from Python (tests/test_process.py): the flag is
    // process-wide, and setting it here would stop the other tests' ray casts.

    #[test]
    fn work_runs_on_the_pool_and_returns() {
        let r = interruptible(
            || Ok(rayon::current_thread_index().is_some()),
            || Ok::<(), ()>(()),
            None,
        );
        assert!(matches!(r, Ok(Ok(true))));
    }

    #[test]
    fn work_here_stays_on_this_thread_and_stops_at_its_poll() {
        let me = std::thread::current().id();
        let r = interruptible_here(
            || Ok(std::thread::current().id()),
            || Ok::<(), ()>(()),
            None,
        );
        assert!(matches!(r, Ok(Ok(id)) if id == me));
        let mut polls = 0;
        let r = interruptible_here(
            || -> Result<()> {
                loop {
                    check()?;
                    std::thread::sleep(Duration::from_millis(1));
                }
            },
            move || {
                polls += 1;
                if polls >= 3 {
                    Err("stop")
                } else {
                    Ok(())
                }
            },
            None,
        );
        assert!(matches!(r, Err("stop")));
        // The poll is gone with its call.
        assert!(check().is_ok());
    }

    #[test]
    fn progress_counts_on_the_work_thread_only() {
        let p = Arc::new(Progress::default());
        let r = interruptible(
            || {
                add_total(10);
                for _ in 0..4 {
                    advance(2);
                }
                Ok(())
            },
            || Ok::<(), ()>(()),
            Some(&p),
        );
        assert!(matches!(r, Ok(Ok(()))));
        assert_eq!(p.total.load(Ordering::Relaxed), 10);
        assert_eq!(p.done.load(Ordering::Relaxed), 8);
        // Outside a counted call, nothing is counted.
        advance(5);
        assert_eq!(p.done.load(Ordering::Relaxed), 8);
    }

    #[test]
    fn a_panicking_job_is_raised_not_waited_for() {
        let r = std::panic::catch_unwind(|| {
            interruptible(
                || -> Result<()> { panic!("boom") },
                || Ok::<(), ()>(()),
                None,
            )
        });
        assert!(r.is_err());
        let again = interruptible(|| Ok(1), || Ok::<(), ()>(()), None);
        assert!(matches!(again, Ok(Ok(1))));
    }

    #[test]
    fn pools_are_made_once_per_size() {
        let a = pool(Some(2)).unwrap();
        let b = pool(Some(2)).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        assert_eq!(install(Some(3), rayon::current_num_threads).unwrap(), 3);
    }
}
