"""Cost of the robot calls on the right-hand-side path: Robot.update + Robot.frame_terms.

Per call, in µs: the median over SAMPLES samples of CALLS calls each, with the 25–75 %
spread, for contactdyn's wrapper and for the same Pinocchio calls made directly (the floor
the wrapper can reach), and the minimum sample. One fixed state per robot; the timed
closures reuse their arrays. The load average is recorded: on a busy machine trust the minimum.

    PYTHONPATH=. python3 benchmarks/robot_calls.py [--samples 200] [--calls 2000]

Prints a table and writes benchmarks/out/robot_calls.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from contactdyn import Robot

OUT = Path(__file__).parent / "out" / "robot_calls.json"
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

# (label, source, frame, load options)
CASES = [
    ("writer2r", "writer2r", "tip", {}),
    ("arm2r_cart (70 % comp.)", "arm2r_cart", "tip", {"gravity_compensation": 0.7}),
    ("cylindrical3 -> q3", "cylindrical3", "tip", {"active_joints": ["q3"]}),
    ("cylindrical3", "cylindrical3", "tip", {}),
    ("writer5dof", "writer5dof", "tip", {}),
    ("ur5", "ur5", "tool0", {}),
    ("panda", "panda", "panda_hand_tcp", {}),
]


def per_call_us(fn, samples: int, calls: int) -> dict[str, float]:
    """Median, quartiles and minimum of the per-call time [µs] over samples of `calls` calls.

    On a shared machine the median carries the other load; the minimum is the best estimate
    of the uncontended cost (timing noise only adds)."""
    for _ in range(calls):  # warm-up
        fn()
    times = np.empty(samples)
    for s in range(samples):
        t0 = time.perf_counter_ns()
        for _ in range(calls):
            fn()
        times[s] = (time.perf_counter_ns() - t0) / calls / 1e3
    p25, p50, p75 = np.percentile(times, [25, 50, 75])
    return {"median": float(p50), "p25": float(p25), "p75": float(p75), "min": float(times.min())}


def measure(source: str, frame: str, options: dict, samples: int, calls: int) -> dict:
    r = Robot.load(source, **options)
    fid = r.frame_id(frame)
    rng = np.random.default_rng(0)
    lo = np.maximum(r.model.lowerPositionLimit, -np.pi)
    hi = np.minimum(r.model.upperPositionLimit, np.pi)
    q, v = rng.uniform(lo, hi), rng.uniform(-1.0, 1.0, r.nv)
    model, data = r.model, pin.Data(r.model)

    def both():
        r.update(q, v)
        return r.frame_terms(fid)

    def raw_both():  # the same Pinocchio calls, no wrapper, no result object, no copies
        pin.computeAllTerms(model, data, q, v)
        pin.updateFramePlacement(model, data, fid)
        pin.getFrameVelocity(model, data, fid, LWA)
        pin.getFrameJacobian(model, data, fid, LWA)
        pin.getFrameClassicalAcceleration(model, data, fid, LWA)

    r.update(q, v)
    return {
        "nv": r.nv,
        "update": per_call_us(lambda: r.update(q, v), samples, calls),
        "frame_terms": per_call_us(lambda: r.frame_terms(fid), samples, calls),
        "update+frame_terms": per_call_us(both, samples, calls),
        "raw pinocchio, same calls": per_call_us(raw_both, samples, calls),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100)
    parser.add_argument("--calls", type=int, default=1000)
    args = parser.parse_args(argv)
    floor = per_call_us(lambda: None, args.samples, args.calls)
    rows = {label: measure(src, frame, opts, args.samples, args.calls) for label, src, frame, opts in CASES}
    columns = ["update", "frame_terms", "update+frame_terms", "raw pinocchio, same calls"]
    load = os.getloadavg()
    print(f"per call [µs]: median (25–75 %) / min of {args.samples} samples x {args.calls} calls; "
          f"empty Python call {floor['median']:.3f} µs; load average {load[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"{'robot':24s} {'nv':>3s} " + " ".join(f"{c:>27s}" for c in columns))
    for label, row in rows.items():
        cells = [f"{row[c]['median']:5.2f} ({row[c]['p25']:5.2f}–{row[c]['p75']:5.2f}) / {row[c]['min']:5.2f}"
                 for c in columns]
        print(f"{label:24s} {row['nv']:3d} " + " ".join(f"{c:>27s}" for c in cells))
    meta = {"python": platform.python_version(), "pinocchio": pin.__version__, "numpy": np.__version__,
            "machine": platform.machine(), "cpus": os.cpu_count(), "samples": args.samples, "calls": args.calls,
            "empty_call_us": floor, "load_average": load}
    OUT.parent.mkdir(exist_ok=True)
    tmp = OUT.with_suffix(".tmp")
    tmp.write_text(json.dumps({"meta": meta, "robots": rows}, indent=2))
    tmp.replace(OUT)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
