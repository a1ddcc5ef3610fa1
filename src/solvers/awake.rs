//! Rayon's other workers kept awake through a run of short parallel passes.
//!
//! **Why.** A rayon worker that finds no work spins a little, then sleeps on a futex; the next
//! parallel loop wakes it. On the 2-core virtual machines these runs use, a wake-up takes tens
//! of microseconds, about what a Sinkhorn iteration's pass over a 2D problem of a few thousand
//! points takes (issue 73): the woken worker arrives when the pass is half done. On dam-2d the
//! fused row pass ran 1.17x faster on two threads than on one. While an [`Awake`] lives, each
//! other worker runs a task that looks for rayon's work without sleeping (`rayon::yield_now`)
//! and runs it: the passes of a solve find their second thread already there. The work and
//! the order of every sum are unchanged; only who waits for it, and how.
//!
//! **The cost.** The other cores spin between the passes, so a guard is held where passes
//! follow one another with little serial work between (Power PIC's transfers), not over a
//! whole step: held over FLIP's step on dam-2d it made the step slower, 0.44-0.47 ms against
//! 0.41-0.43 (docs/benchmarks/powerpic.md).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// While it lives, rayon's other workers look for work without sleeping (see the module doc).
pub struct Awake {
    done: Arc<AtomicBool>,
}

impl Awake {
    /// Keeps the current pool's other workers awake until the guard is dropped. A pool of one
    /// thread, or a caller outside any pool, spawns nothing.
    pub fn start() -> Self {
        let done = Arc::new(AtomicBool::new(false));
        if let Some(me) = rayon::current_thread_index() {
            for _ in 1..rayon::current_num_threads() {
                let done = done.clone();
                rayon::spawn(move || keep_looking(me, &done));
            }
        }
        Self { done }
    }
}

#[cfg(test)]
impl Awake {
    /// The guard's flag, which each spinner holds a handle of from its spawning until it
    /// returns: the spinners alive are its handles but the guard's and this one.
    fn spinners(&self) -> Arc<AtomicBool> {
        self.done.clone()
    }
}

impl Drop for Awake {
    fn drop(&mut self) {
        self.done.store(true, Ordering::Release);
    }
}

/// A spinner's loop: runs whatever rayon work it finds until `done`. On the thread `owner`
/// that made the guard it returns at once: that thread took its own spinner off its queue
/// while it waited for work (it would spin there, and never get back to dropping the guard).
fn keep_looking(owner: usize, done: &AtomicBool) {
    if rayon::current_thread_index() == Some(owner) {
        return;
    }
    while !done.load(Ordering::Acquire) {
        if rayon::yield_now() != Some(rayon::Yield::Executed) {
            std::hint::spin_loop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;
    use std::sync::mpsc;
    use std::time::Duration;

    fn pool(threads: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool")
    }

    /// Runs `f` on another thread; fails if it has not returned within a minute (a spinner
    /// that never stops would hang the test instead of failing it).
    fn within_a_minute(f: impl FnOnce() + Send + 'static) {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            f();
            tx.send(()).expect("the test waits");
        });
        rx.recv_timeout(Duration::from_secs(60))
            .expect("finished within a minute");
    }

    #[test]
    fn the_passes_run_while_awake_and_the_spinners_stop_after() {
        within_a_minute(|| {
            let pool = pool(2);
            for _ in 0..100 {
                let spinners = pool.install(|| {
                    let awake = Awake::start();
                    let sum: u64 = (0..10_000u32)
                        .into_par_iter()
                        .with_min_len(100)
                        .map(u64::from)
                        .sum();
                    assert_eq!(sum, 10_000 * 9_999 / 2);
                    awake.spinners()
                });
                // The guard is gone: each spinner lets go of the flag when it returns.
                while Arc::strong_count(&spinners) > 1 {
                    std::thread::yield_now();
                }
            }
        });
    }

    #[test]
    fn a_thread_that_takes_its_own_spinner_returns_from_it() {
        within_a_minute(|| {
            let pool = pool(2);
            let (release, wait) = mpsc::channel::<()>();
            let (held, started) = mpsc::channel::<()>();
            let started = std::sync::Mutex::new(started);
            pool.install(|| {
                // The other worker is held, so the spinner stays on this thread's queue,
                // and yielding runs it here.
                rayon::spawn(move || {
                    held.send(()).expect("the test waits");
                    wait.recv().expect("released")
                });
                started
                    .lock()
                    .expect("one waiter")
                    .recv()
                    .expect("the other worker holds");
                let _awake = Awake::start();
                while rayon::yield_local() == Some(rayon::Yield::Executed) {}
                release.send(()).expect("the worker waits");
            });
        });
    }

    #[test]
    fn outside_a_pool_or_on_one_thread_nothing_spins() {
        within_a_minute(|| {
            let alive = |a: &Awake| Arc::strong_count(&a.spinners()) - 2;
            assert_eq!(alive(&Awake::start()), 0, "outside any pool");
            assert_eq!(pool(1).install(|| alive(&Awake::start())), 0, "one thread");
            // The count sees a spinner: on two threads there is one.
            assert_eq!(pool(2).install(|| alive(&Awake::start())), 1, "two threads");
        });
    }
}
