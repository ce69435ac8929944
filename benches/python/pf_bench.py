#!/usr/bin/env python3
"""Baseline for benches/filters.rs: a vectorised numpy SIR particle filter with 6
pseudoranges (state [x, y, z, b], random-walk prediction, Gaussian pseudorange likelihood,
N_eff-threshold systematic resampling), timed with timeit at 100, 500 and 10 000
particles. Prints microseconds per epoch and pseudorange likelihood terms per second
(particles x measurements / time), both for the likelihood alone and for the whole epoch.
"""
import sys
import timeit

try:
    import numpy as np
except ImportError:
    print("skipped: numpy not installed")
    sys.exit(3)


def main():
    rng = np.random.default_rng(7)
    emitters = np.array([
        [15_600e3, 7_540e3, 20_140e3],
        [18_760e3, 2_750e3, 18_610e3],
        [17_610e3, 14_630e3, 13_480e3],
        [19_170e3, 610e3, 18_390e3],
        [-2_000e3, 12_000e3, 21_000e3],
        [5_000e3, -14_000e3, 20_000e3],
    ])
    truth = np.array([-2_177e3, 4_389e3, 4_070e3, 30.0])
    sigma = np.full(6, 3.0)
    z = np.linalg.norm(emitters - truth[:3], axis=1) + truth[3] + rng.normal(0, 3.0, 6)
    neg_half_inv_var = -0.5 / sigma**2
    q_std = np.array([1.0, 1.0, 1.0, 0.5])

    for n in (100, 500, 10_000):
        x = truth + rng.normal(0, 10.0, (n, 4))
        w = np.full(n, 1.0 / n)

        def loglik():
            d = np.sqrt(((emitters[None, :, :] - x[:, None, :3]) ** 2).sum(axis=2)) + x[:, 3:4] - z
            return (d * d * neg_half_inv_var).sum(axis=1)

        def epoch():
            nonlocal x, w
            x = x + rng.normal(0, 1.0, (n, 4)) * q_std
            ll = loglik()
            w = w * np.exp(ll - ll.max())
            w /= w.sum()
            neff = 1.0 / np.sum(w * w)
            if neff < 0.5 * n:
                c = np.cumsum(w)
                c[-1] = np.inf
                idx = np.searchsorted(c, (rng.random() + np.arange(n)) / n)
                x = x[idx]
                w = np.full(n, 1.0 / n)

        reps = max(20, 200_000 // n)
        t_lik = min(timeit.repeat(loglik, number=reps, repeat=5)) / reps
        t_ep = min(timeit.repeat(epoch, number=reps, repeat=5)) / reps
        terms = n * 6
        print(f"numpy SIR N={n}: likelihood {t_lik * 1e6:.1f} us ({terms / t_lik / 1e6:.1f} M terms/s), "
              f"epoch {t_ep * 1e6:.1f} us ({terms / t_ep / 1e6:.1f} M terms/s)")


if __name__ == "__main__":
    main()
