//! Parallel map over work items: rayon with the `parallel` feature, a plain loop without.
//! Results keep the items' order, so reductions over them are deterministic for any thread
//! count.

/// `items.map(f).collect()`, in parallel when the `parallel` feature is on.
#[cfg(feature = "parallel")]
pub(crate) fn map<I, R, F>(items: Vec<I>, f: F) -> Vec<R>
where
    I: Send,
    R: Send,
    F: Fn(I) -> R + Sync + Send,
{
    use rayon::prelude::*;
    items.into_par_iter().map(f).collect()
}

/// `items.map(f).collect()`, in parallel when the `parallel` feature is on.
#[cfg(not(feature = "parallel"))]
pub(crate) fn map<I, R, F>(items: Vec<I>, f: F) -> Vec<R>
where
    F: Fn(I) -> R,
{
    items.into_iter().map(f).collect()
}

/// `items.map(|i| f(&mut state, i)).collect()`, where `state` comes from a pool: at most
/// one is made (by `init`) per concurrently running item, i.e. per worker thread, and they
/// are reused across items (large buffers are allocated and faulted in once).
pub(crate) fn map_pooled<I, S, R, F, G>(items: Vec<I>, init: G, f: F) -> Vec<R>
where
    I: Send,
    R: Send,
    S: Send,
    G: Fn() -> S + Sync + Send,
    F: Fn(&mut S, I) -> R + Sync + Send,
{
    let pool = std::sync::Mutex::new(Vec::new());
    let take = || pool.lock().map(|mut p| p.pop()).ok().flatten();
    map(items, |i| {
        let mut s = take().unwrap_or_else(&init);
        let r = f(&mut s, i);
        if let Ok(mut p) = pool.lock() {
            p.push(s);
        }
        r
    })
}

/// Worker threads that [`map`] spreads items over (1 without the `parallel` feature).
pub(crate) fn threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "parallel"))]
    {
        1
    }
}
