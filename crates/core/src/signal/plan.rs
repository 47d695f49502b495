//! A thread-safe cache of FFT plans (real-to-complex, complex-to-real and complex).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::{Fft, FftPlanner};

/// A cache of `realfft` plans (forward, and inverse for the few users that need one) keyed by
/// transform length, and of `rustfft` complex plans (the order tracker's demodulation, the TSA's
/// order masks), shareable between threads: the one FFT plan cache of the crate.
///
/// Planning an FFT (choosing the algorithm, computing twiddle factors) costs far more than one
/// transform of a short record, so [`amplitude_spectrum`](super::amplitude_spectrum) and
/// [`welch`](super::welch) take their plans from [`PlanCache::global`]: repeated calls with the
/// same length plan once. Plans are immutable and `Send + Sync`, so a plan fetched here may be
/// used from any thread (e.g. inside a rayon parallel iterator); the lock is held only while
/// looking a plan up or creating it, never during a transform.
pub struct PlanCache {
    inner: Mutex<Inner>,
}

struct Inner {
    planner: RealFftPlanner<f64>,
    plans: HashMap<usize, Arc<dyn RealToComplex<f64>>>,
    inverse: HashMap<usize, Arc<dyn ComplexToReal<f64>>>,
    /// Complex plans; rustfft's planner keeps the plans it made.
    complex: FftPlanner<f64>,
}

impl Default for PlanCache {
    fn default() -> Self {
        Self::new()
    }
}

impl std::fmt::Debug for PlanCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PlanCache")
            .field("cached_lengths", &self.lengths())
            .finish()
    }
}

impl PlanCache {
    /// An empty cache.
    pub fn new() -> Self {
        PlanCache {
            inner: Mutex::new(Inner {
                planner: RealFftPlanner::new(),
                plans: HashMap::new(),
                inverse: HashMap::new(),
                complex: FftPlanner::new(),
            }),
        }
    }

    /// The process-wide cache used by the spectrum functions of this module.
    pub fn global() -> &'static PlanCache {
        static GLOBAL: OnceLock<PlanCache> = OnceLock::new();
        GLOBAL.get_or_init(PlanCache::new)
    }

    /// Lock, recovering from a poisoned mutex (the cache holds no invariant a panic could
    /// break: at worst a plan is missing and gets planned again).
    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The forward real FFT plan for `len` samples (output `len/2 + 1` complex bins,
    /// unnormalised: `X_k = Σ x_n e^{−2πikn/len}`). Planned on first request, then shared.
    pub fn forward(&self, len: usize) -> Arc<dyn RealToComplex<f64>> {
        let mut g = self.lock();
        if let Some(p) = g.plans.get(&len) {
            return Arc::clone(p);
        }
        let p = g.planner.plan_fft_forward(len);
        g.plans.insert(len, Arc::clone(&p));
        p
    }

    /// The inverse (complex-to-real) plan for `len` output samples (input `len/2 + 1` bins,
    /// unnormalised). Planned on first request, then shared; not counted by [`PlanCache::len`]
    /// and [`PlanCache::lengths`], which describe the forward plans.
    pub fn inverse(&self, len: usize) -> Arc<dyn ComplexToReal<f64>> {
        let mut g = self.lock();
        if let Some(p) = g.inverse.get(&len) {
            return Arc::clone(p);
        }
        let p = g.planner.plan_fft_inverse(len);
        g.inverse.insert(len, Arc::clone(&p));
        p
    }

    /// The complex FFT plan for `len` points, forward (`X_k = Σ x_n e^{−2πikn/len}`) or
    /// `inverse` (`e^{+2πikn/len}`), both unnormalised. Planned on first request, then shared;
    /// not counted by [`PlanCache::len`] and [`PlanCache::lengths`].
    pub fn complex(&self, len: usize, inverse: bool) -> Arc<dyn Fft<f64>> {
        let mut g = self.lock();
        if inverse {
            g.complex.plan_fft_inverse(len)
        } else {
            g.complex.plan_fft_forward(len)
        }
    }

    /// Whether an inverse plan for `len` samples is already cached.
    pub fn contains_inverse(&self, len: usize) -> bool {
        self.lock().inverse.contains_key(&len)
    }

    /// Whether a plan for `len` samples is already cached.
    pub fn contains(&self, len: usize) -> bool {
        self.lock().plans.contains_key(&len)
    }

    /// Number of cached plans.
    pub fn len(&self) -> usize {
        self.lock().plans.len()
    }

    /// True if no plan has been cached yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The cached lengths, ascending.
    pub fn lengths(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self.lock().plans.keys().copied().collect();
        v.sort_unstable();
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_length_returns_same_plan() {
        let c = PlanCache::new();
        assert!(c.is_empty());
        let a = c.forward(96);
        let b = c.forward(96);
        assert!(Arc::ptr_eq(&a, &b));
        assert_eq!(a.len(), 96);
        let _ = c.forward(17);
        assert_eq!(c.lengths(), vec![17, 96]);
        assert!(c.contains(17) && !c.contains(18));
        let i = c.inverse(96);
        assert!(Arc::ptr_eq(&i, &c.inverse(96)));
        assert_eq!(i.len(), 96);
        assert!(c.contains_inverse(96) && !c.contains_inverse(17));
        assert_eq!(c.len(), 2);
    }

    #[test]
    fn usable_from_many_threads() {
        let c = PlanCache::new();
        let plans: Vec<_> = std::thread::scope(|s| {
            let hs: Vec<_> = (0..4).map(|_| s.spawn(|| c.forward(128))).collect();
            hs.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert_eq!(c.len(), 1);
        for p in &plans[1..] {
            assert!(Arc::ptr_eq(&plans[0], p));
        }
    }
}
