//! A small work queue: the diagnosis runs many independent simulations.

use std::sync::Mutex;

/// Runs `jobs` on up to `threads` threads, results in job order.
pub(crate) fn parallel<T: Send, R: Send>(threads: usize, jobs: Vec<T>, f: &(dyn Fn(T) -> R + Sync)) -> Vec<R> {
    let n = jobs.len();
    let queue = Mutex::new(jobs.into_iter().enumerate().collect::<Vec<_>>());
    let out = Mutex::new((0..n).map(|_| None).collect::<Vec<Option<R>>>());
    std::thread::scope(|s| {
        for _ in 0..threads.clamp(1, n.max(1)) {
            s.spawn(|| loop {
                let job = queue.lock().unwrap().pop();
                let Some((i, job)) = job else { break };
                let r = f(job);
                out.lock().unwrap()[i] = Some(r);
            });
        }
    });
    out.into_inner()
        .unwrap()
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}
