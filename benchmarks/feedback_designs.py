"""Feedback designs compared: integral + notch (the default), a wide notch and PI + notch
(``pi_zero``).

Controllers designed on a model identified from 0.1 s of noisy reference-stage data (as in
notebook 2), driving the true stage with the feed-forward inverse; tracking after the first period.
The measurement is :func:`bench_tracking.measure_designs`, which also gives the README's
``feedback-designs`` block (``python benchmarks/readme.py --only feedback-designs``).

Usage: python benchmarks/feedback_designs.py
"""

from __future__ import annotations

import argparse

from _common import write_json
from bench_tracking import identified_model, measure_designs, render_designs

from hystid.reference import reference_model


def main() -> None:
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    designs = measure_designs(identified_model(), reference_model())
    print("Feedback designs on the identified model, driving the reference stage "
          "(feed-forward inverse + feedback)")
    print(render_designs({"designs": designs}))
    print(f"wrote {write_json('feedback_designs', designs)}")


if __name__ == "__main__":
    main()
