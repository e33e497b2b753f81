//! Data parallelism of the kernels: one rayon pool per run, sized by the run's thread budget
//! ([`Threads`]) and entered once around its set-up and its time loop; the kernels below
//! split their work over the pool they are called in.
//!
//! **Determinism.** Every kernel cuts its index range into chunks of a fixed length that does
//! not depend on the number of threads, and a reduction adds its chunks' partial results in
//! chunk order on the calling thread. A kernel's result is therefore the same bits for any
//! thread count, one included: runs with 1, 2 or 16 threads give identical numbers, and
//! threads are a setting of the machine, never of the computation (not in a scene or its
//! hash).
//!
//! Outside a pool (unit tests, the tools) the same chunks run in order on the calling thread:
//! rayon's global pool is never used, so jobs of a multi-worker node never oversubscribe it.

use rayon::prelude::*;
use std::ops::Range;
use std::sync::Arc;

/// Elements per chunk of the vector kernels (axpy, dot products, norms): 128 KiB of f64,
/// large against rayon's cost of a task (about a microsecond), small against the vectors of a
/// mesh worth splitting. Unit tests split the small meshes they run, so that every kernel's
/// threaded path is exercised.
pub const VECTOR_CHUNK: usize = if cfg!(test) { 256 } else { 16 * 1024 };

/// Rows per chunk of the sparse products: about 80 000 stored entries on a 3D elasticity row
/// block.
pub const ROW_CHUNK: usize = if cfg!(test) { 32 } else { 1024 };

/// A run's thread budget: `count` threads in a pool of its own (none for one thread).
#[derive(Clone)]
pub struct Threads {
    pool: Option<Arc<rayon::ThreadPool>>,
    count: usize,
}

impl std::fmt::Debug for Threads {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Threads({})", self.count)
    }
}

impl Threads {
    /// A pool of `count` threads (`count` ≥ 1; 1 makes no pool: everything runs on the
    /// caller's thread).
    pub fn new(count: usize) -> Threads {
        let count = count.max(1);
        let pool = (count > 1).then(|| {
            Arc::new(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(count)
                    .thread_name(|i| format!("contact-sim-{i}"))
                    .build()
                    .expect("a thread pool of the requested size"),
            )
        });
        Threads { pool, count }
    }

    /// One thread, no pool.
    pub fn one() -> Threads {
        Threads::new(1)
    }

    /// The machine's cores (1 when unknown): the command line's default budget.
    pub fn available() -> usize {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    }

    pub fn count(&self) -> usize {
        self.count
    }

    /// Runs `f` with the kernels it calls split over this budget's threads (on the caller's
    /// thread when the budget is one).
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        match &self.pool {
            Some(pool) => pool.install(f),
            None => f(),
        }
    }
}

/// True when called on a thread of a pool with more than one thread: the kernels split.
fn splitting() -> bool {
    rayon::current_thread_index().is_some() && rayon::current_num_threads() > 1
}

/// The number of threads the calling kernel may use (1 outside a pool).
pub fn current_threads() -> usize {
    match rayon::current_thread_index() {
        Some(_) => rayon::current_num_threads(),
        None => 1,
    }
}

/// Calls `f(start, chunk)` for the consecutive chunks of `chunk_len` elements of `y`, where
/// `start` is the chunk's first index in `y`.
pub fn for_each_chunk_mut<T: Send>(
    y: &mut [T],
    chunk_len: usize,
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    // A zero-sized scratch: the same chunks, nothing made per thread.
    for_each_chunk_mut_with(y, chunk_len, || (), |_, start, chunk| f(start, chunk));
}

/// [`for_each_chunk_mut`] with scratch: `f(scratch, start, chunk)`, the scratch made by
/// `init` once for each run of chunks a thread takes (a few per call, not one per chunk), so
/// that a chunk's transient storage is not allocated and faulted in afresh every time.
/// `f` must not let what a chunk leaves in the scratch change another chunk's result.
pub fn for_each_chunk_mut_with<T: Send, S>(
    y: &mut [T],
    chunk_len: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [T]) + Sync + Send,
) {
    if splitting() && y.len() > chunk_len {
        y.par_chunks_mut(chunk_len)
            .enumerate()
            .for_each_init(init, |s, (i, c)| f(s, i * chunk_len, c));
    } else {
        let mut s = init();
        y.chunks_mut(chunk_len)
            .enumerate()
            .for_each(|(i, c)| f(&mut s, i * chunk_len, c));
    }
}

/// `f(start, a_chunk, b_chunk)` over the consecutive chunks of `chunk_len` elements of two
/// slices of one length, the results in order (fused vector updates with a reduction).
pub fn map_chunks2_mut<R: Send>(
    a: &mut [f64],
    b: &mut [f64],
    chunk_len: usize,
    f: impl Fn(usize, &mut [f64], &mut [f64]) -> R + Sync + Send,
) -> Vec<R> {
    assert_eq!(a.len(), b.len());
    if splitting() && a.len() > chunk_len {
        a.par_chunks_mut(chunk_len)
            .zip(b.par_chunks_mut(chunk_len))
            .enumerate()
            .map(|(i, (a, b))| f(i * chunk_len, a, b))
            .collect()
    } else {
        a.chunks_mut(chunk_len)
            .zip(b.chunks_mut(chunk_len))
            .enumerate()
            .map(|(i, (a, b))| f(i * chunk_len, a, b))
            .collect()
    }
}

/// `f` over the consecutive ranges of `chunk_len` indices of 0..n, the results in order.
pub fn map_ranges<R: Send>(
    n: usize,
    chunk_len: usize,
    f: impl Fn(Range<usize>) -> R + Sync + Send,
) -> Vec<R> {
    let chunks = n.div_ceil(chunk_len);
    let range = |i: usize| i * chunk_len..((i + 1) * chunk_len).min(n);
    if splitting() && chunks > 1 {
        (0..chunks).into_par_iter().map(|i| f(range(i))).collect()
    } else {
        (0..chunks).map(|i| f(range(i))).collect()
    }
}

/// The rows of a sparse pattern formed on the pool's threads: row r holds what `row(r, out)`
/// appends to `out`, sorted and without duplicates. Returns (ptr, entries), row r being
/// `entries[ptr[r]..ptr[r + 1]]`; blocks of rows are joined in order.
pub fn sorted_rows<T: Ord + Copy + Send>(
    n: usize,
    row: impl Fn(usize, &mut Vec<T>) + Sync + Send,
) -> (Vec<usize>, Vec<T>) {
    let blocks = map_ranges(n, ROW_CHUNK, |rows| {
        let (mut lengths, mut out) = (Vec::with_capacity(rows.len()), Vec::new());
        for r in rows {
            let first = out.len();
            row(r, &mut out);
            out[first..].sort_unstable();
            let mut kept = first;
            for q in first..out.len() {
                if q == first || out[q] != out[kept - 1] {
                    out[kept] = out[q];
                    kept += 1;
                }
            }
            out.truncate(kept);
            lengths.push(kept - first);
        }
        (lengths, out)
    });
    join_rows(n, blocks)
}

/// The `n` rows of consecutive blocks of rows (each its rows' lengths and their entries in
/// row order) as one CSR-style (offsets, entries), in vectors of their final size.
pub fn join_rows<T>(n: usize, blocks: Vec<(Vec<usize>, Vec<T>)>) -> (Vec<usize>, Vec<T>) {
    let mut ptr = Vec::with_capacity(n + 1);
    ptr.push(0);
    let mut entries = Vec::with_capacity(blocks.iter().map(|b| b.1.len()).sum());
    for (lengths, out) in blocks {
        for l in lengths {
            ptr.push(ptr.last().unwrap() + l);
        }
        entries.extend(out);
    }
    assert_eq!(ptr.len(), n + 1, "the blocks cover the rows");
    (ptr, entries)
}

/// Σ f(range) over the chunks of 0..n, added in chunk order: the same bits for any thread
/// count.
pub fn sum(n: usize, f: impl Fn(Range<usize>) -> f64 + Sync + Send) -> f64 {
    map_ranges(n, VECTOR_CHUNK, f)
        .into_iter()
        .fold(0.0, |s, p| s + p)
}

/// aᵀb.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    sum(a.len(), |r| {
        a[r.clone()].iter().zip(&b[r]).map(|(x, y)| x * y).sum()
    })
}

/// max |aᵢ| (0 for an empty vector).
pub fn max_abs(a: &[f64]) -> f64 {
    map_ranges(a.len(), VECTOR_CHUNK, |r| {
        a[r].iter().fold(0.0f64, |m, v| m.max(v.abs()))
    })
    .into_iter()
    .fold(0.0, f64::max)
}

/// yᵢ ← f(yᵢ, xᵢ) elementwise.
pub fn zip_apply(y: &mut [f64], x: &[f64], f: impl Fn(f64, f64) -> f64 + Sync + Send) {
    debug_assert_eq!(x.len(), y.len());
    for_each_chunk_mut(y, VECTOR_CHUNK, |start, yc| {
        let n = yc.len();
        for (y, &x) in yc.iter_mut().zip(&x[start..start + n]) {
            *y = f(*y, x);
        }
    });
}

/// y ← x, in chunks on the pool's threads.
pub fn copy(y: &mut [f64], x: &[f64]) {
    assert_eq!(x.len(), y.len());
    for_each_chunk_mut(y, VECTOR_CHUNK, |start, yc| {
        let n = yc.len();
        yc.copy_from_slice(&x[start..start + n]);
    });
}

/// yᵢ ← v, in chunks on the pool's threads.
pub fn fill(y: &mut [f64], v: f64) {
    for_each_chunk_mut(y, VECTOR_CHUNK, |_, yc| yc.fill(v));
}

/// min aᵢ (+∞ for an empty vector).
pub fn min(a: &[f64]) -> f64 {
    map_ranges(a.len(), VECTOR_CHUNK, |r| {
        a[r].iter().fold(f64::INFINITY, |m, &v| m.min(v))
    })
    .into_iter()
    .fold(f64::INFINITY, f64::min)
}

/// Calls `f(segment, piece)` for the pieces of `y` between consecutive `bounds` (increasing,
/// from 0 to `y.len()`): a split where chunks must end at given indices (node blocks).
pub fn for_each_segment_mut<T: Send>(
    y: &mut [T],
    bounds: &[usize],
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    debug_assert_eq!(bounds.first().copied().unwrap_or(0), 0);
    debug_assert_eq!(bounds.last().copied().unwrap_or(0), y.len());
    let mut pieces = Vec::with_capacity(bounds.len().saturating_sub(1));
    let mut rest = y;
    for w in bounds.windows(2) {
        let (piece, tail) = rest.split_at_mut(w[1] - w[0]);
        pieces.push(piece);
        rest = tail;
    }
    if splitting() && pieces.len() > 1 {
        pieces
            .into_par_iter()
            .enumerate()
            .for_each(|(s, piece)| f(s, piece));
    } else {
        pieces
            .into_iter()
            .enumerate()
            .for_each(|(s, piece)| f(s, piece));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vector(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    #[test]
    fn reductions_are_the_same_bits_for_every_thread_count() {
        let n = 5 * VECTOR_CHUNK + 123;
        let (a, b) = (vector(n, 1), vector(n, 2));
        let one = (dot(&a, &b), max_abs(&a), min(&a));
        for t in [2, 3, 4] {
            let many = Threads::new(t).install(|| (dot(&a, &b), max_abs(&a), min(&a)));
            assert_eq!(one.0.to_bits(), many.0.to_bits(), "{t} threads");
            assert_eq!((one.1, one.2), (many.1, many.2));
        }
        assert_eq!(one.2, a.iter().cloned().fold(f64::INFINITY, f64::min));
        // And the chunked sum is the plain sum to rounding.
        let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((one.0 - plain).abs() <= 1e-12 * n as f64);
        assert_eq!(one.1, a.iter().fold(0.0f64, |m, v| m.max(v.abs())));
    }

    #[test]
    fn chunked_maps_cover_every_index_once_in_order() {
        let n = 3 * ROW_CHUNK + 7;
        let ranges = Threads::new(3).install(|| map_ranges(n, ROW_CHUNK, |r| r));
        let flat: Vec<usize> = ranges.into_iter().flatten().collect();
        assert_eq!(flat, (0..n).collect::<Vec<_>>());
        let mut y = vec![0.0; n];
        Threads::new(2).install(|| {
            for_each_chunk_mut(&mut y, ROW_CHUNK, |s, c| {
                c.iter_mut()
                    .enumerate()
                    .for_each(|(i, v)| *v += (s + i) as f64)
            })
        });
        assert!(y.iter().enumerate().all(|(i, &v)| v == i as f64));
        let x = vector(n, 3);
        Threads::new(2).install(|| copy(&mut y, &x));
        assert_eq!(y, x);
        Threads::new(2).install(|| fill(&mut y, 0.25));
        assert!(y.iter().all(|&v| v == 0.25));
    }

    #[test]
    fn chunks_with_scratch_cover_every_index_once_and_one_thread_makes_one_scratch() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let chunks = 64;
        let n = chunks * 100 - 37;
        for t in [1, 2, 4] {
            let made = AtomicUsize::new(0);
            let mut y = vec![0.0; n];
            Threads::new(t).install(|| {
                let init = || {
                    made.fetch_add(1, Ordering::Relaxed);
                    0usize
                };
                for_each_chunk_mut_with(&mut y, 100, init, |uses, s, c| {
                    *uses += 1;
                    c.iter_mut()
                        .enumerate()
                        .for_each(|(i, v)| *v += (s + i) as f64)
                })
            });
            assert!(y.iter().enumerate().all(|(i, &v)| v == i as f64), "{t}");
            // Rayon makes one scratch for each run of chunks a thread takes: how many runs
            // depends on stealing, at most one a chunk; one thread takes them all in one.
            let made = made.into_inner();
            assert!(
                (1..=chunks).contains(&made),
                "{made} scratches for {chunks} chunks"
            );
            if t == 1 {
                assert_eq!(made, 1);
            }
        }
    }

    #[test]
    fn a_pool_reports_its_size_and_no_pool_is_one_thread() {
        assert_eq!(current_threads(), 1);
        assert_eq!(Threads::new(3).install(current_threads), 3);
        assert_eq!(Threads::one().install(current_threads), 1);
    }
}
