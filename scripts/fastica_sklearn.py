#!/usr/bin/env python3
"""scikit-learn's FastICA on the mixtures written by
`cargo run --release -p idmesh-sensor --example acoustic_fastica_compare`.

Usage: fastica_sklearn.py INPUT.json OUTPUT.json

INPUT holds cases, each a list of repetitions {x: m×T mixtures, a: m×n
mixing matrix, s: n×T true sources}. For every repetition this runs
FastICA with the settings idmesh uses (parallel/symmetric, logcosh with
alpha 1, tol 1e-4, max_iter 200, unit-variance whitening, n_components =
number of sources) and records the wall time of `fit_transform` alone,
the Amari index of components_ @ A and, for each true source, the best
|corr| with an estimated one. Needs numpy and scikit-learn installed
(`pip install scikit-learn numpy`); installs nothing itself.
"""

import json
import sys
import time
import warnings


def amari_index(p):
    import numpy as np

    a = np.abs(p)
    r, c = a.shape
    rows = (a.sum(axis=1) / a.max(axis=1) - 1.0).sum()
    cols = (a.sum(axis=0) / a.max(axis=0) - 1.0).sum()
    return float((rows + cols) / (r * (max(c, 2) - 1) + c * (max(r, 2) - 1)))


def max_abs_corr(s_true, s_est):
    import numpy as np

    n = s_true.shape[0]
    c = np.corrcoef(np.vstack([s_true, s_est]))[:n, n:]
    return [float(v) for v in np.nanmax(np.abs(c), axis=1)]


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        import numpy as np
        from sklearn.decomposition import FastICA
        from sklearn.exceptions import ConvergenceWarning
    except ImportError as e:
        print(f"fastica_sklearn.py: {e}; run `pip install scikit-learn numpy` first", file=sys.stderr)
        return 3
    with open(sys.argv[1]) as f:
        cases = json.load(f)["cases"]
    out = {"sklearn": __import__("sklearn").__version__, "numpy": np.__version__, "cases": []}
    for case in cases:
        results = []
        for i, rep in enumerate(case["reps"]):
            x = np.asarray(rep["x"], dtype=np.float64)
            a = np.asarray(rep["a"], dtype=np.float64)
            s = np.asarray(rep["s"], dtype=np.float64)
            n = s.shape[0]
            ica = FastICA(
                n_components=n,
                algorithm="parallel",
                fun="logcosh",
                fun_args={"alpha": 1.0},
                whiten="unit-variance",
                whiten_solver="svd",
                max_iter=200,
                tol=1e-4,
                random_state=i,
            )
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", ConvergenceWarning)
                t0 = time.perf_counter()
                est = ica.fit_transform(x.T).T  # sklearn wants samples × features
                seconds = time.perf_counter() - t0
            converged = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
            results.append(
                {
                    "seconds": seconds,
                    "iterations": int(ica.n_iter_),
                    "converged": converged,
                    "amari": amari_index(ica.components_ @ a),
                    "max_corr": max_abs_corr(s, est),
                }
            )
        out["cases"].append({"name": case["name"], "results": results})
    with open(sys.argv[2], "w") as f:
        json.dump(out, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
