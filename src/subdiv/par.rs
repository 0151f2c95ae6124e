//! Parallel-or-sequential loops over disjoint output slices (rayon behind the `parallel`
//! feature). Every helper writes each output element from exactly one closure call, so the
//! results are identical whatever the thread count.

/// Below this many work items a loop runs sequentially (thread hand-off costs more).
#[cfg(feature = "parallel")]
const MIN_PARALLEL: usize = 1 << 14;

/// Whether a loop of `n` items is handed to the thread pool (`min` and more items): not when
/// the pool has a single thread, which would run the same work sequentially while the caller
/// waits, and each hand-off costs two context switches (on a busy machine, a wait for the
/// scheduler each).
#[cfg(feature = "parallel")]
fn parallel(n: usize, min: usize) -> bool {
    n >= min && rayon::current_num_threads() > 1
}

/// Calls `f(i, chunk_i)` for consecutive chunks of `chunk` elements.
pub(crate) fn for_each_chunk_mut<T: Send>(
    data: &mut [T],
    chunk: usize,
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    #[cfg(feature = "parallel")]
    if parallel(data.len(), MIN_PARALLEL) {
        use rayon::prelude::*;
        data.par_chunks_mut(chunk)
            .enumerate()
            .with_min_len(1024)
            .for_each(|(i, c)| f(i, c));
        return;
    }
    for (i, c) in data.chunks_mut(chunk).enumerate() {
        f(i, c);
    }
}

/// Calls `f(i, x_i)` for every element.
pub(crate) fn for_each_mut<T: Send>(data: &mut [T], f: impl Fn(usize, &mut T) + Sync + Send) {
    #[cfg(feature = "parallel")]
    if parallel(data.len(), MIN_PARALLEL) {
        use rayon::prelude::*;
        data.par_iter_mut()
            .enumerate()
            .with_min_len(2048)
            .for_each(|(i, x)| f(i, x));
        return;
    }
    for (i, x) in data.iter_mut().enumerate() {
        f(i, x);
    }
}

/// Calls `f(i, x_i)` for every element, in parallel from two elements on: for elements that
/// each take long (a base triangle's measurement over thousands of points), where
/// [`for_each_mut`]'s threshold would keep a few thousand of them on one thread.
pub(crate) fn for_each_heavy<T: Send>(data: &mut [T], f: impl Fn(usize, &mut T) + Sync + Send) {
    #[cfg(feature = "parallel")]
    if parallel(data.len(), 2) {
        use rayon::prelude::*;
        data.par_iter_mut().enumerate().for_each(|(i, x)| f(i, x));
        return;
    }
    for (i, x) in data.iter_mut().enumerate() {
        f(i, x);
    }
}

/// `f(i)` for every `i` in `0..n`, in order, in parallel from two items on (for items that
/// each take long, as [`for_each_heavy`]). The encoder's per-face work is its only user.
#[cfg(feature = "encoder")]
pub(crate) fn map_heavy<R: Send>(n: usize, f: impl Fn(usize) -> R + Sync + Send) -> Vec<R> {
    #[cfg(feature = "parallel")]
    if parallel(n, 2) {
        use rayon::prelude::*;
        return (0..n).into_par_iter().map(f).collect();
    }
    (0..n).map(f).collect()
}

/// Calls `f(i, segment_i)` where segment i is `data[offsets[i]..offsets[i + 1]]`
/// (`offsets[0] == 0`, `offsets.last() == data.len()`).
pub(crate) fn for_each_segment_mut<T: Send>(
    data: &mut [T],
    offsets: &[u32],
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    let n = offsets.len().saturating_sub(1);
    #[cfg(feature = "parallel")]
    if parallel(data.len(), MIN_PARALLEL) {
        use rayon::prelude::*;
        const BLOCK: usize = 4096;
        let mut blocks: Vec<(usize, &mut [T])> = Vec::with_capacity(n / BLOCK + 1);
        let mut rest = data;
        let mut start = 0;
        while start < n {
            let end = (start + BLOCK).min(n);
            let len = (offsets[end] - offsets[start]) as usize;
            let (head, tail) = rest.split_at_mut(len);
            blocks.push((start, head));
            rest = tail;
            start = end;
        }
        blocks.into_par_iter().for_each(|(s, block)| {
            let base = offsets[s] as usize;
            let end = (s + BLOCK).min(n);
            for i in s..end {
                let (a, b) = (offsets[i] as usize - base, offsets[i + 1] as usize - base);
                f(i, &mut block[a..b]);
            }
        });
        return;
    }
    for i in 0..n {
        f(i, &mut data[offsets[i] as usize..offsets[i + 1] as usize]);
    }
}

/// Appends `f(0), f(1), .., f(n - 1)` to `out` (in order, without zero-filling first).
pub(crate) fn extend_mapped<T: Send>(
    out: &mut Vec<T>,
    n: usize,
    f: impl Fn(usize) -> T + Sync + Send,
) {
    #[cfg(feature = "parallel")]
    if parallel(n, MIN_PARALLEL) {
        use rayon::prelude::*;
        out.par_extend((0..n).into_par_iter().with_min_len(2048).map(f));
        return;
    }
    out.extend((0..n).map(f));
}
