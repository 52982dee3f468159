//! Per-frame work on a decoded stream, in parallel and in order.
//!
//! A decoder is an iterator that cannot leave its thread (a pipe from `ffmpeg`, a codec's
//! state), while the work on each frame (pre-processing, a metric frame) is independent of
//! the others. [`map_in_order`] reads a batch of frames on the calling thread while the
//! previous batch is mapped on the thread pool, and hands the results back in stream
//! order, so the output is the same whatever the number of threads.

use rayon::prelude::*;

/// Most items [`map_in_order`] batches, whatever the thread count or item size.
pub const MAX_BATCH: usize = 64;

/// A batch length for [`map_in_order`] over items of about `item_bytes` each: two per
/// thread (one batch is read while the other is mapped), with at most `budget_bytes`
/// of items in one batch, never fewer than 1 nor more than [`MAX_BATCH`].
pub fn batch_len(item_bytes: usize, budget_bytes: usize) -> usize {
    let by_memory = budget_bytes / item_bytes.max(1);
    (2 * rayon::current_num_threads())
        .min(by_memory)
        .clamp(1, MAX_BATCH)
}

/// Maps every item of `items` with `f` on the thread pool, `batch` items at a time (the
/// next batch is read on this thread meanwhile), and calls `consume` with each item and
/// its result in the order of `items`.
///
/// Stops at the first error of `items` (the items before it are mapped and consumed
/// first) or of `consume` (no later item is consumed), and returns it. At most two batches
/// of items are held at once.
pub fn map_in_order<T, U, E, I, F, C>(
    items: I,
    batch: usize,
    f: F,
    mut consume: C,
) -> std::result::Result<(), E>
where
    I: IntoIterator<Item = std::result::Result<T, E>>,
    T: Send + Sync,
    U: Send,
    F: Fn(&T) -> U + Sync,
    C: FnMut(T, U) -> std::result::Result<(), E>,
{
    let batch = batch.clamp(1, MAX_BATCH);
    // fused: a batch that ended the stream is followed by one more read
    let mut items = items.into_iter().fuse();
    let (mut cur, mut failed) = read_batch(&mut items, batch);
    while !cur.is_empty() {
        let mut mapped: Vec<U> = Vec::new();
        let mut next = (Vec::new(), None);
        let reading = failed.is_none();
        rayon::in_place_scope(|s| {
            let (cur, f, mapped) = (&cur, &f, &mut mapped);
            s.spawn(move |_| *mapped = cur.par_iter().map(f).collect());
            if reading {
                next = read_batch(&mut items, batch);
            }
        });
        for (t, u) in cur.into_iter().zip(mapped) {
            consume(t, u)?;
        }
        if let Some(e) = failed {
            return Err(e);
        }
        (cur, failed) = next;
    }
    failed.map_or(Ok(()), Err)
}

/// Up to `n` items, and the error that ended them early, if one did.
fn read_batch<T, E>(
    items: &mut impl Iterator<Item = std::result::Result<T, E>>,
    n: usize,
) -> (Vec<T>, Option<E>) {
    let mut out = Vec::with_capacity(n);
    for item in items.by_ref() {
        match item {
            Ok(t) => out.push(t),
            Err(e) => return (out, Some(e)),
        }
        if out.len() == n {
            break;
        }
    }
    (out, None)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(items: Vec<Result<u32, String>>, batch: usize) -> (Vec<(u32, u64)>, Result<(), String>) {
        let mut seen = Vec::new();
        let r = map_in_order(
            items,
            batch,
            |&x| u64::from(x) * u64::from(x),
            |t, u| {
                seen.push((t, u));
                Ok(())
            },
        );
        (seen, r)
    }

    #[test]
    fn results_come_back_in_stream_order_at_any_batch_and_thread_count() {
        let items: Vec<Result<u32, String>> = (0..1000).map(Ok).collect();
        let want: Vec<(u32, u64)> = (0..1000).map(|x| (x, u64::from(x * x))).collect();
        for threads in [1, 2, 5] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for batch in [0, 1, 3, 64, 5000] {
                let (seen, r) = pool.install(|| run(items.clone(), batch));
                assert_eq!(r, Ok(()));
                assert_eq!(seen, want, "{threads} threads, batch {batch}");
            }
        }
        // from a thread outside any pool, as the CLI's main thread
        assert_eq!(run(items, 4).0, want);
    }

    #[test]
    fn a_read_error_comes_after_the_items_before_it() {
        let mut items: Vec<Result<u32, String>> = (0..10).map(Ok).collect();
        items[7] = Err("bad frame 7".into());
        for batch in [1, 2, 3, 4, 7, 8, 20] {
            let (seen, r) = run(items.clone(), batch);
            assert_eq!(r, Err("bad frame 7".into()), "batch {batch}");
            let got: Vec<u32> = seen.iter().map(|p| p.0).collect();
            assert_eq!(got, (0..7).collect::<Vec<_>>(), "batch {batch}");
        }
    }

    #[test]
    fn a_consume_error_stops_at_that_item() {
        for batch in [1, 2, 3, 8] {
            let mut seen = Vec::new();
            let r = map_in_order(
                (0..10u32).map(Ok::<u32, String>),
                batch,
                |&x| x + 1,
                |t, u| {
                    if t == 4 {
                        return Err(format!("refused {t}"));
                    }
                    seen.push(u);
                    Ok(())
                },
            );
            assert_eq!(r, Err("refused 4".into()));
            assert_eq!(seen, vec![1, 2, 3, 4], "batch {batch}");
        }
    }

    #[test]
    fn no_item_is_read_past_a_take() {
        // a decoder must not be asked for frames past the count wanted
        let mut pulled = 0;
        let it = std::iter::from_fn(|| {
            pulled += 1;
            Some(Ok::<u32, String>(pulled))
        })
        .take(5);
        let mut n = 0;
        map_in_order(
            it,
            3,
            |&x| x,
            |_, _| {
                n += 1;
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(n, 5);
        assert_eq!(pulled, 5);
    }

    #[test]
    fn batch_len_is_bounded() {
        assert_eq!(batch_len(1 << 40, 1 << 20), 1);
        assert!(batch_len(1, usize::MAX) <= MAX_BATCH);
        assert!(batch_len(0, 0) >= 1);
    }
}
