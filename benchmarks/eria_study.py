"""Why the published ERIA does not converge: starts, noise levels and ablations.

Runs the paper's recursion (eqs. 15-19, rho(k) = (k+1)^-9/13, P(0) = 1e6 I) on the reference
stage, literally (``recover=False``: only a non-finite estimate is restarted), from several
starts and noise levels, then switches off one suspected cause at a time:

* ``mu=1``: no forgetting (the paper's mu(k) is 0.62 at k=1 and still 0.95 at k=100);
* ``Lambda floor``: Lambda^-1(k) kept above the noise variance (it collapses to ~0 on clean data,
  which turns the gain into a projection);
* ``oracle internal``: internal signals w1, w2 and the products in h from the TRUE parameters
  (cuts the estimate -> internal-signal -> regressor loop).

Usage: python benchmarks/eria_study.py [--quick]
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from _common import table, write_json

from hystid.identify.eria import DIAGNOSTICS, ERIA
from hystid.reference import PAPER_PARAMS, reference_record

TRUTH = np.array(list(PAPER_PARAMS.values()))


def run(rec, theta0, **settings) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        est = ERIA(theta0=theta0, truth=PAPER_PARAMS, **settings)
        res = est.fit(rec)
    err = np.max(np.abs(res.history - TRUTH) / np.abs(TRUTH), axis=1)
    diag = res.info["diagnostics"]
    out = np.flatnonzero(err > 0.02)
    beta = diag[:, DIAGNOSTICS.index("beta")]
    band = np.sqrt(np.clip(diag[:, DIAGNOSTICS.index("delta1")], 0, None))
    ok = np.isfinite(beta) & np.isfinite(band)
    outside = np.abs(beta[ok] - 1.0) > band[ok]
    return {
        "beta_outside_band": float(outside.mean()) if ok.any() else None,
        "err_after_1000": float(err[1000:].max()) if len(err) > 1000 else None,
        "left_2pc_at": int(out[0]) + 1 if len(out) else None,
        "max_err": float(err.max()), "final_err": float(err[-1]),
        "restarts": res.info["n_recoveries"],
        "min_lambda_inv": float(np.nanmin(diag[:, DIAGNOSTICS.index("lambda_inv")])),
        "max_lambda_max_P": float(np.nanmax(diag[:, DIAGNOSTICS.index("lambda_max")])),
        "final_cond_P": float(diag[-1, DIAGNOSTICS.index("cond_P")]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="6 000 samples, 1 seed")
    args = parser.parse_args()
    n = 6_000 if args.quick else 30_000
    seeds = [0] if args.quick else [0, 1, 2]
    starts = {"truth": PAPER_PARAMS, "truth +1 %": TRUTH * 1.01, "truth +10 %": TRUTH * 1.1,
              "0.01 (paper)": 0.01}
    variants = {
        "paper (literal)": {"recover": False},
        "mu = 1": {"recover": False, "mu": 1.0},
        "Lambda floor": {"recover": False, "lambda_inv_min": 1e-6},
        "mu = 1 + floor": {"recover": False, "mu": 1.0, "lambda_inv_min": 1e-6},
        "oracle internal": {"recover": False, "internal": PAPER_PARAMS},
        "oracle + mu = 1 + floor": {"recover": False, "internal": PAPER_PARAMS, "mu": 1.0,
                                    "lambda_inv_min": 1e-6},
    }
    rows, records = [], []
    for noise in (0.0, 1e-3, 1e-2):
        for seed in seeds:
            rec = reference_record(n / 30_000.0, seed=seed, noise=noise)
            for vname, settings in variants.items():
                for sname, theta0 in starts.items():
                    if vname != "paper (literal)" and sname not in ("truth", "0.01 (paper)"):
                        continue
                    r = run(rec, theta0, **settings)
                    records.append({"noise_nm": noise * 1e3, "seed": seed, "variant": vname,
                                    "start": sname, **r})
    for noise in (0.0, 1.0, 10.0):
        for vname in variants:
            for sname in starts:
                rs = [r for r in records if r["noise_nm"] == noise and r["variant"] == vname
                      and r["start"] == sname]
                if not rs:
                    continue
                left = [r["left_2pc_at"] for r in rs]
                rows.append([
                    f"{noise:g}", vname, sname,
                    "never" if all(v is None for v in left) else
                    str(min(v for v in left if v is not None)),
                    f"{np.median([r['final_err'] for r in rs]):.3g}",
                    f"{max(r['err_after_1000'] for r in rs):.3g}",
                    f"{np.mean([r['beta_outside_band'] for r in rs]):.0%}",
                    str(sum(r["restarts"] for r in rs)),
                    f"{min(r['min_lambda_inv'] for r in rs):.1e}",
                    f"{max(r['max_lambda_max_P'] for r in rs):.1e}",
                ])
    print(f"ERIA on the reference stage, {n} samples, seeds {seeds}; errors are max relative "
          "parameter errors")
    print(table(rows, ["noise nm", "variant", "start", "first >2 % at", "final err",
                       "max err after k=1000", "beta outside band", "restarts",
                       "min Lambda^-1", "max lambda_max(P)"]))
    path = write_json("eria_study", {"samples": n, "seeds": seeds, "rows": records})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
