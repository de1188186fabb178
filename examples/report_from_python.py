"""A drift report from Python: the same rows ``inspector report`` prints, as data to work with.

Usage::

    python examples/report_from_python.py [SESSION]      # default: the bundled demo session

Prints the three rollouts whose predicted arm drifts furthest from the real one (time-aligned drift,
degrees) and the aggregate over every rollout, then the report's text tables.
"""

from __future__ import annotations

import sys

from inspector.data.sources import BUNDLED_DEMO
from inspector.report import build_report, format_report


def main(argv: list[str]) -> int:
    path = argv[0] if argv else str(BUNDLED_DEMO)
    report = build_report([path], jobs=1, progress=False)
    autoregressive = [row for row in report["rollouts"] if row["kind"] == "autoregressive"]
    worst = sorted(autoregressive, key=lambda row: -row["time_aligned_drift"]["mean"])[:3]
    for row in worst:
        print(f"{row['tag']:<20} time-aligned drift {row['time_aligned_drift']['mean']:6.2f} deg, "
              f"tempo {row['tempo']:.2f}")
    aggregate = report["aggregate"]
    print(f"{aggregate['n']} rollouts: chunk RMSE mean {aggregate['mean_rmse_deg']:.3f} deg, "
          f"worst {aggregate['worst_rmse_deg']:.3f} deg")
    print()
    print(format_report(report))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
