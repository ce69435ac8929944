//! Exact order statistics of more values than a run should hold in memory: an external
//! merge sort.
//!
//! A Monte Carlo run of 10 000 trials scores tens of millions of epochs; its σ-levels are
//! exact percentiles of all of them. [`SortedSpill`] keeps at most [`SortedSpill::chunk`]
//! values in memory: each full chunk is sorted and written to a run file, and a pass over
//! the values merges the runs (a k-way merge). The values come out in `f64::total_cmp`
//! order, exactly as sorting them all in memory would give, so every statistic computed
//! from the sorted sequence is bit-identical to the in-memory computation (ties are
//! equal bit patterns, so their order cannot matter). A run that fits in one chunk never
//! touches the disk.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::fs;
use std::io::{self, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Values held in memory before a sorted run goes to disk: 64 Ki values, 512 KiB.
pub const DEFAULT_CHUNK: usize = 1 << 16;

/// Distinguishes the spills of one process (several estimators and metrics at once).
static NEXT_SPILL: AtomicU64 = AtomicU64::new(0);

/// A multiset of `f64` that can be read back in sorted order any number of times.
#[derive(Debug)]
pub struct SortedSpill {
    dir: PathBuf,
    stem: String,
    chunk: usize,
    buf: Vec<f64>,
    runs: Vec<PathBuf>,
    len: usize,
    non_finite: usize,
}

impl SortedSpill {
    /// An empty spill whose run files (if any) go into `dir`, which must exist.
    pub fn new(dir: &Path) -> Self {
        Self::with_chunk(dir, DEFAULT_CHUNK)
    }

    /// As [`SortedSpill::new`] with `chunk` values per run (at least 1); tests use tiny
    /// chunks to exercise the merge.
    pub fn with_chunk(dir: &Path, chunk: usize) -> Self {
        let id = NEXT_SPILL.fetch_add(1, Ordering::Relaxed);
        Self {
            dir: dir.to_path_buf(),
            stem: format!(".hybridnav-spill-{}-{id}", std::process::id()),
            chunk: chunk.max(1),
            buf: Vec::new(),
            runs: Vec::new(),
            len: 0,
            non_finite: 0,
        }
    }

    /// Finite values pushed so far (the ones it keeps).
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Values pushed that were NaN or infinite, counted and not kept.
    pub fn non_finite(&self) -> usize {
        self.non_finite
    }

    /// Values per sorted run.
    pub fn chunk(&self) -> usize {
        self.chunk
    }

    /// Adds a value.
    ///
    /// # Errors
    /// When a full chunk cannot be written to its run file (the message names it).
    pub fn push(&mut self, v: f64) -> io::Result<()> {
        // Statistics of a diverged estimator are withheld, not computed over NaN: the
        // count says that happened, and the finite values still give the CDF.
        if !v.is_finite() {
            self.non_finite += 1;
            return Ok(());
        }
        self.buf.push(v);
        self.len += 1;
        if self.buf.len() >= self.chunk {
            self.flush_run()?;
        }
        Ok(())
    }

    /// Adds every value of `values`.
    ///
    /// # Errors
    /// As [`SortedSpill::push`].
    pub fn extend(&mut self, values: &[f64]) -> io::Result<()> {
        for &v in values {
            self.push(v)?;
        }
        Ok(())
    }

    fn flush_run(&mut self) -> io::Result<()> {
        self.buf.sort_by(f64::total_cmp);
        let path = self
            .dir
            .join(format!("{}-{}.f64", self.stem, self.runs.len()));
        let result = (|| {
            let mut w = BufWriter::new(fs::File::create(&path)?);
            for v in &self.buf {
                w.write_all(&v.to_le_bytes())?;
            }
            w.flush()
        })();
        // The run is registered before the error is returned so that drop removes a
        // partly written file too.
        self.runs.push(path.clone());
        result.map_err(|e| io::Error::new(e.kind(), format!("writing {}: {e}", path.display())))?;
        self.buf.clear();
        Ok(())
    }

    /// Calls `f(i, v)` for every value in ascending `total_cmp` order, `i` its 0-based
    /// rank. Sorts the in-memory chunk first (hence `&mut`), then merges it with the runs.
    ///
    /// # Errors
    /// When a run file cannot be read back.
    pub fn for_each_sorted(&mut self, mut f: impl FnMut(usize, f64)) -> io::Result<()> {
        self.buf.sort_by(f64::total_cmp);
        if self.runs.is_empty() {
            for (i, &v) in self.buf.iter().enumerate() {
                f(i, v);
            }
            return Ok(());
        }
        let mut readers = Vec::with_capacity(self.runs.len());
        for p in &self.runs {
            let file = fs::File::open(p)
                .map_err(|e| io::Error::new(e.kind(), format!("reading {}: {e}", p.display())))?;
            readers.push((BufReader::with_capacity(1 << 16, file), p));
        }
        let read_one = |r: &mut (BufReader<fs::File>, &PathBuf)| -> io::Result<Option<f64>> {
            let mut b = [0u8; 8];
            match r.0.read_exact(&mut b) {
                Ok(()) => Ok(Some(f64::from_le_bytes(b))),
                Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => Ok(None),
                Err(e) => Err(io::Error::new(
                    e.kind(),
                    format!("reading {}: {e}", r.1.display()),
                )),
            }
        };
        // The heap orders by the value's total-order key, then by source, so the merge is
        // deterministic; source `readers.len()` is the in-memory chunk.
        let mut heap = BinaryHeap::with_capacity(readers.len() + 1);
        for (k, r) in readers.iter_mut().enumerate() {
            if let Some(v) = read_one(r)? {
                heap.push(Reverse((Key(v), k)));
            }
        }
        let mem = readers.len();
        let mut mem_next = 0usize;
        if let Some(&v) = self.buf.first() {
            heap.push(Reverse((Key(v), mem)));
            mem_next = 1;
        }
        let mut i = 0usize;
        while let Some(Reverse((Key(v), k))) = heap.pop() {
            f(i, v);
            i += 1;
            let next = if k == mem {
                let n = self.buf.get(mem_next).copied();
                mem_next += 1;
                n
            } else {
                read_one(&mut readers[k])?
            };
            if let Some(n) = next {
                heap.push(Reverse((Key(n), k)));
            }
        }
        Ok(())
    }
}

impl Drop for SortedSpill {
    fn drop(&mut self) {
        for p in &self.runs {
            let _ = fs::remove_file(p);
        }
    }
}

/// `f64` ordered by `total_cmp`, for the merge heap.
#[derive(Clone, Copy, Debug)]
struct Key(f64);

impl PartialEq for Key {
    fn eq(&self, other: &Self) -> bool {
        self.0.total_cmp(&other.0).is_eq()
    }
}
impl Eq for Key {}
impl PartialOrd for Key {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Key {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use rand::Rng;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hybridnav-spill-{name}-{}", std::process::id()));
        fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn merged_runs_equal_an_in_memory_sort_bit_for_bit() {
        let d = tmp("merge");
        let mut rng = TrialRng::new(7, 0).stream("spill");
        for (n, chunk) in [(0usize, 3usize), (1, 1), (10, 3), (1000, 7), (5000, 4096)] {
            let values: Vec<f64> = (0..n)
                .map(|i| {
                    // Repeated values and signed zeros exercise ties and the total order.
                    match i % 11 {
                        0 => 1.5,
                        1 => -0.0,
                        2 => 0.0,
                        _ => rng.random::<f64>() * 100.0 - 20.0,
                    }
                })
                .collect();
            let mut s = SortedSpill::with_chunk(&d, chunk);
            s.extend(&values).unwrap();
            let mut got = Vec::new();
            s.for_each_sorted(|i, v| {
                assert_eq!(i, got.len());
                got.push(v.to_bits());
            })
            .unwrap();
            // A second pass gives the same sequence.
            let mut again = Vec::new();
            s.for_each_sorted(|_, v| again.push(v.to_bits())).unwrap();
            let mut want = values.clone();
            want.sort_by(f64::total_cmp);
            let want: Vec<u64> = want.iter().map(|v| v.to_bits()).collect();
            assert_eq!(got, want, "n {n} chunk {chunk}");
            assert_eq!(again, want);
            assert_eq!(s.len(), n);
            if n > chunk {
                assert!(fs::read_dir(&d).unwrap().count() > 0, "runs were spilled");
            }
            drop(s);
            assert_eq!(fs::read_dir(&d).unwrap().count(), 0, "run files removed");
        }
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn counts_non_finite_values_and_names_an_unwritable_directory() {
        let d = tmp("nf");
        let mut s = SortedSpill::with_chunk(&d, 100);
        s.extend(&[1.0, f64::NAN, f64::INFINITY, 2.0]).unwrap();
        assert_eq!((s.non_finite(), s.len()), (2, 2));
        let mut kept = Vec::new();
        s.for_each_sorted(|_, v| kept.push(v)).unwrap();
        assert_eq!(kept, [1.0, 2.0]);
        let mut bad = SortedSpill::with_chunk(Path::new("/nonexistent-hybridnav-dir"), 2);
        bad.push(1.0).unwrap();
        let e = bad.push(2.0).unwrap_err();
        assert!(e.to_string().contains("/nonexistent-hybridnav-dir"), "{e}");
        fs::remove_dir_all(&d).unwrap();
    }
}
