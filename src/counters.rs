//! Counts of the expensive operations a call did, so that each result can say what its own call
//! ran (cube maps built, splat passes, shadow-map views, rays cast) and a caller (the effect
//! planner's tests) can prove which ones ran.
//!
//! The counts belong to the call whose work runs on the current thread: [`tally`] opens a count
//! around a piece of work, and [`add`] adds to the innermost open one on this thread (nothing
//! when none is open). Two calls on two threads never see each other's counts. Operations are
//! counted where a call starts them (its own thread), not inside its parallel workers.

use std::cell::RefCell;

/// What one call did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Ops {
    pub cube_maps: u64,
    pub splat_passes: u64,
    pub shadow_views: u64,
    pub rays_cast: u64,
}

/// One kind of counted operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    CubeMaps,
    SplatPasses,
    ShadowViews,
    RaysCast,
}

impl Ops {
    fn slot(&mut self, op: Op) -> &mut u64 {
        match op {
            Op::CubeMaps => &mut self.cube_maps,
            Op::SplatPasses => &mut self.splat_passes,
            Op::ShadowViews => &mut self.shadow_views,
            Op::RaysCast => &mut self.rays_cast,
        }
    }

    /// (name, count) of every kind, in a fixed order.
    pub fn named(&self) -> [(&'static str, u64); 4] {
        [
            ("cube_maps", self.cube_maps),
            ("splat_passes", self.splat_passes),
            ("shadow_views", self.shadow_views),
            ("rays_cast", self.rays_cast),
        ]
    }

    fn absorb(&mut self, o: &Ops) {
        self.cube_maps += o.cube_maps;
        self.splat_passes += o.splat_passes;
        self.shadow_views += o.shadow_views;
        self.rays_cast += o.rays_cast;
    }
}

thread_local! {
    /// The open counts on this thread, innermost last.
    static OPEN: RefCell<Vec<Ops>> = const { RefCell::new(Vec::new()) };
}

/// Count `n` operations of kind `op` for the call running on this thread.
pub fn add(op: Op, n: u64) {
    OPEN.with(|o| {
        if let Some(top) = o.borrow_mut().last_mut() {
            *top.slot(op) += n;
        }
    });
}

/// Close the innermost open count, adding it to the one around it, and return it.
fn close() -> Ops {
    OPEN.with(|o| {
        let mut o = o.borrow_mut();
        let mine = o.pop().unwrap_or_default();
        if let Some(outer) = o.last_mut() {
            outer.absorb(&mine);
        }
        mine
    })
}

/// Closes the count if the work panics, so the thread's stack stays balanced.
struct Open;

impl Drop for Open {
    fn drop(&mut self) {
        close();
    }
}

/// Run `f` and return what it did. A count opened inside another one also adds to the outer.
pub fn tally<R>(f: impl FnOnce() -> R) -> (R, Ops) {
    OPEN.with(|o| o.borrow_mut().push(Ops::default()));
    let open = Open;
    let r = f();
    std::mem::forget(open);
    (r, close())
}

/// Run `f` without counting what it does towards the calls around it (the backend cost model's
/// probes are not the caller's work).
pub fn uncounted<R>(f: impl FnOnce() -> R) -> R {
    OPEN.with(|o| o.borrow_mut().push(Ops::default()));
    struct Discard;
    impl Drop for Discard {
        fn drop(&mut self) {
            OPEN.with(|o| o.borrow_mut().pop());
        }
    }
    let _discard = Discard;
    f()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_belong_to_their_call_and_nest() {
        add(Op::RaysCast, 5); // nobody counts: dropped
        let ((_, inner), outer) = tally(|| {
            add(Op::CubeMaps, 1);
            tally(|| add(Op::RaysCast, 3))
        });
        assert_eq!(inner.rays_cast, 3);
        assert_eq!((outer.cube_maps, outer.rays_cast), (1, 3));
        // Another thread's call sees only its own.
        let other = std::thread::spawn(|| tally(|| add(Op::SplatPasses, 2)).1);
        let ((), here) = tally(|| add(Op::ShadowViews, 6));
        assert_eq!(other.join().unwrap().splat_passes, 2);
        assert_eq!((here.shadow_views, here.splat_passes), (6, 0));
        let ((), around) = tally(|| uncounted(|| add(Op::RaysCast, 7)));
        assert_eq!(around.rays_cast, 0);
    }
}
