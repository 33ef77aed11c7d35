//! Whether a batch of queries is worth spreading over the thread pool.
//!
//! Handing work to a rayon pool whose threads sleep costs their wake-up: tens of microseconds
//! on a busy or virtual machine, more than a small batch takes on the calling thread (a
//! thousand rays through a small scene, a simulator's usual call). So a batch first answers a
//! few queries on the calling thread, timed ([`Probe`]), and hands the rest to the pool only
//! when, at that pace, they would take longer than [`SPLIT_MIN`]. Which thread answers a query
//! never changes its answer. Figures in `docs/engine_frame_loop.md`.

use rayon::prelude::*;
use std::time::{Duration, Instant};

/// Queries answered on the calling thread before a batch is judged.
pub const PROBE: usize = 32;

/// The least work, at the probe's pace, worth waking the pool for.
pub const SPLIT_MIN: Duration = Duration::from_micros(100);

/// The probe stops early, after at least [`PROBE_FEW`] queries, once the rest at its pace
/// would take this many times [`SPLIT_MIN`]: its queries run one after the other while the
/// pool waits, and on a costly batch a few already settle the question.
const CLEAR_SPLIT: f64 = 2.0;
/// The fewest queries a probe answers before it may stop early.
const PROBE_FEW: usize = 4;

/// A batch's first queries, answered on the calling thread and timed: [`PROBE`] of them spread
/// evenly over the batch (the `k`-th of them at `k * len / PROBE`), so that a batch whose cost is
/// uneven along it (a camera image's empty corners first) is judged by its mean; fewer when the
/// first few already show a long batch (`CLEAR_SPLIT`).
#[derive(Clone, Copy, Debug)]
pub struct Probe {
    elapsed: Duration,
    /// Items answered, of `len`.
    answered: usize,
    len: usize,
    /// The items of [`Probe::run`]: the first `spread` of `planned` evenly over the batch.
    spread: usize,
    planned: usize,
}

impl Probe {
    /// Calls `answer(i)` for [`PROBE`] items spread over a batch of `len`, timed; stops early
    /// once the pace of the first `PROBE_FEW` (then 8, 16, ...) shows the rest would take
    /// `CLEAR_SPLIT` times [`SPLIT_MIN`]. The clock is read only at those counts: a read
    /// after every item costs about what a cheap query does, and would count as one.
    pub fn run(len: usize, answer: impl FnMut(usize)) -> Self {
        let clear = CLEAR_SPLIT * SPLIT_MIN.as_secs_f64();
        Self::run_until(len, answer, |elapsed, answered| {
            elapsed.as_secs_f64() / answered as f64 * (len - answered) as f64 >= clear
        })
    }

    /// [`Probe::run`] with the early stop `stop(elapsed, answered)`, asked after
    /// [`PROBE_FEW`] items and at every doubling of the count after that, short of the last.
    fn run_until(
        len: usize,
        mut answer: impl FnMut(usize),
        stop: impl Fn(Duration, usize) -> bool,
    ) -> Self {
        let planned = PROBE.min(len);
        let start = Instant::now();
        let mut spread = 0;
        let mut check = PROBE_FEW;
        while spread < planned {
            answer(spread_item(spread, planned, len));
            spread += 1;
            if spread == check && spread < planned {
                check *= 2;
                if stop(start.elapsed(), spread) {
                    break;
                }
            }
        }
        Self {
            elapsed: start.elapsed(),
            answered: spread,
            len,
            spread,
            planned,
        }
    }

    /// Times `answer`, which answers `count` items of a batch of `len` (the caller knows
    /// which: [`Probe::taken`] names none).
    pub fn timed(count: usize, len: usize, answer: impl FnOnce()) -> Self {
        let start = Instant::now();
        answer();
        Self {
            elapsed: start.elapsed(),
            answered: count.min(len),
            len,
            spread: 0,
            planned: 0,
        }
    }

    /// What the probe's items took.
    #[must_use]
    pub fn elapsed(&self) -> Duration {
        self.elapsed
    }

    /// How many items the probe answered.
    #[must_use]
    pub fn count(&self) -> usize {
        self.answered
    }

    /// The items [`Probe::run`] answered in `from..to`, in order.
    pub fn taken(&self, from: usize, to: usize) -> impl Iterator<Item = usize> + Clone {
        let (spread, planned, len) = (self.spread, self.planned, self.len);
        // The first `k` whose item is at `from` or after: `k * len / planned >= from`.
        let first = if planned == 0 {
            0
        } else {
            (from as u128 * planned as u128).div_ceil(len as u128) as usize
        };
        (first..spread)
            .map(move |k| spread_item(k, planned, len))
            .take_while(move |&i| i < to)
    }

    /// Whether the rest of the batch is worth the pool: it has more than one thread and the
    /// rest, at the probe's pace, would take at least [`SPLIT_MIN`] on one.
    #[must_use]
    pub fn split(&self) -> bool {
        let left = self.len - self.answered;
        if left == 0 || rayon::current_num_threads() < 2 {
            return false;
        }
        let per = self.elapsed.as_secs_f64() / self.answered.max(1) as f64;
        per * left as f64 >= SPLIT_MIN.as_secs_f64()
    }
}

/// The `k`-th of `planned` items evenly over a batch of `len`.
fn spread_item(k: usize, planned: usize, len: usize) -> usize {
    (k as u128 * len as u128 / planned as u128) as usize
}

/// `out[i] = f(&items[i])` for every item: [`PROBE`] of them on the calling thread, the rest
/// there too or over the pool in runs of `run` (see the module's doc).
///
/// # Panics
/// When `out` and `items` differ in length.
pub fn map<I: Sync, O: Send>(items: &[I], out: &mut [O], run: usize, f: impl Fn(&I) -> O + Sync) {
    assert_eq!(items.len(), out.len(), "one output per item");
    let probe = Probe::run(items.len(), |i| out[i] = f(&items[i]));
    let rest = |base: usize, o: &mut [O], r: &[I]| {
        let mut taken = probe.taken(base, base + r.len());
        let mut next = taken.next().map_or(usize::MAX, |i| i - base);
        for (j, (o, it)) in o.iter_mut().zip(r).enumerate() {
            if j == next {
                next = taken.next().map_or(usize::MAX, |i| i - base);
                continue;
            }
            *o = f(it);
        }
    };
    if probe.split() {
        let run = run.max(1);
        chunks(true, items, out, run, |c, o, r| rest(c * run, o, r));
    } else {
        rest(0, out, items);
    }
}

/// `f(k, out_chunk, items_chunk)` for the `k`-th chunks of `size` of `out` and `items`: over
/// the pool when `split`, else in order on the calling thread.
///
/// # Panics
/// When `size` is 0.
pub fn chunks<I: Sync, O: Send>(
    split: bool,
    items: &[I],
    out: &mut [O],
    size: usize,
    f: impl Fn(usize, &mut [O], &[I]) + Sync,
) {
    if split {
        out.par_chunks_mut(size)
            .zip(items.par_chunks(size))
            .enumerate()
            .for_each(|(k, (o, r))| f(k, o, r));
    } else {
        for (k, (o, r)) in out.chunks_mut(size).zip(items.chunks(size)).enumerate() {
            f(k, o, r);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn in_pool(threads: usize, f: impl FnOnce() + Send) {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(f);
    }

    #[test]
    fn a_small_batch_stays_on_the_calling_thread() {
        // Cheap items: the whole batch takes far less than the pool's wake-up.
        let items: Vec<u32> = (0..1000).collect();
        let mut out = vec![(0, None); items.len()];
        in_pool(2, || {
            let here = std::thread::current().id();
            map(&items, &mut out, 64, |&i| {
                (i * 2, Some(std::thread::current().id()))
            });
            assert!(out.iter().all(|o| o.1 == Some(here)));
        });
        assert!(out.iter().enumerate().all(|(i, o)| o.0 == 2 * i as u32));
    }

    #[test]
    fn a_long_batch_is_split_over_the_pool_with_the_same_answers() {
        // Each item sleeps: at the probe's pace the rest takes far more than `SPLIT_MIN`.
        let items: Vec<u32> = (0..PROBE as u32 + 64).collect();
        let mut out = vec![(0, None); items.len()];
        in_pool(2, || {
            map(&items, &mut out, 4, |&i| {
                std::thread::sleep(Duration::from_micros(200));
                (i + 7, rayon::current_thread_index())
            });
        });
        assert!(out.iter().enumerate().all(|(i, o)| o.0 == i as u32 + 7));
        let threads: std::collections::HashSet<_> = out.iter().map(|o| o.1).collect();
        assert!(
            threads.len() >= 2,
            "the rest ran on one thread: {threads:?}"
        );
    }

    #[test]
    fn one_thread_never_splits_and_empty_batches_are_fine() {
        let slow = |len| Probe::run(len, |_| std::thread::sleep(Duration::from_millis(1)));
        in_pool(1, || assert!(!slow(1_000_000).split()));
        in_pool(2, || {
            assert!(slow(1_000_000).split() && !slow(PROBE_FEW - 1).split())
        });
        let mut out: Vec<u8> = vec![];
        map(&[] as &[u8], &mut out, 8, |&x| x);
    }

    #[test]
    fn a_probe_of_a_clearly_long_batch_stops_after_a_few() {
        let mut seen = vec![];
        let p = Probe::run(1_000_000, |i| {
            seen.push(i);
            std::thread::sleep(Duration::from_micros(50));
        });
        assert_eq!(seen.len(), PROBE_FEW);
        assert_eq!(p.count(), PROBE_FEW);
        assert_eq!(p.taken(0, 1_000_000).collect::<Vec<_>>(), seen);
        in_pool(2, || assert!(p.split()));
    }

    #[test]
    fn the_early_stop_is_asked_after_a_few_and_at_each_doubling() {
        let asked = std::cell::RefCell::new(vec![]);
        let p = Probe::run_until(
            1000,
            |_| {},
            |_, n| {
                asked.borrow_mut().push(n);
                false
            },
        );
        assert_eq!(p.count(), PROBE);
        assert_eq!(*asked.borrow(), vec![PROBE_FEW, 8, 16]);
        // A stop at the second check ends the probe there.
        let p = Probe::run_until(1000, |_| {}, |_, n| n >= 8);
        assert_eq!(p.count(), 8);
        assert_eq!(p.taken(0, 1000).count(), 8);
    }

    #[test]
    fn the_probe_spreads_over_the_batch_and_names_what_it_took() {
        for len in [
            0,
            1,
            5,
            PROBE,
            PROBE + 1,
            2 * PROBE - 1,
            3 * PROBE + 2,
            1000,
            4099,
        ] {
            // Without the early stop, which depends on the clock (the test is of the spread).
            let mut seen = vec![];
            let p = Probe::run_until(len, |i| seen.push(i), |_, _| false);
            assert_eq!(seen.len(), PROBE.min(len));
            assert!(seen.iter().all(|&i| i < len));
            assert_eq!(p.taken(0, len).collect::<Vec<_>>(), seen);
            // Any cut of the batch names the same items.
            for cut in [0, 1, len / 3, len / 2, len] {
                let mut both: Vec<_> = p.taken(0, cut).collect();
                both.extend(p.taken(cut, len));
                assert_eq!(both, seen, "len {len} cut {cut}");
            }
            // Evenly: no gap between items, nor after the last, longer than the batch's share.
            let gaps = seen
                .windows(2)
                .map(|w| w[1] - w[0])
                .chain(seen.last().map(|l| len - l));
            assert!(
                gaps.into_iter().all(|g| g <= len.div_ceil(PROBE)),
                "len {len}: {seen:?}"
            );
        }
    }
}
