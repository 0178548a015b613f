"""Memory of a least-change fit with many reference points (issue 26: linear in the point count), run by hand:
``homocal fit --method least-change`` under ``/usr/bin/time -v`` (its peak resident set) and a ``homocal ui``
server answering POST /api/fit with the same points (its peak resident set, VmHWM, before and after).

    python benchmarks/bench_reference_points.py [--points 20000]

Prints one line per measurement. The points are probe_bad_inputs.py's: distinct image points below the horizon
of its trapezoid, their mapped ground positions moved by up to 5 cm.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from probe_bad_inputs import TRAP, _many_points  # noqa: E402


def peak_kb(pid: int) -> int:
    """VmHWM of a running process, kB."""
    return next(int(line.split()[1]) for line in open(f"/proc/{pid}/status") if line.startswith("VmHWM"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=20_000)
    n = parser.parse_args().points
    d = Path(tempfile.mkdtemp(prefix="bench_ref_"))
    (d / "trap.json").write_text(json.dumps(TRAP))
    _many_points("ref.csv", n)(d)
    fit = subprocess.run(["/usr/bin/time", "-v", sys.executable, "-m", "homocal.cli", "fit", "--trapezoid", "trap.json",
                          "--points", "ref.csv", "--method", "least-change", "-o", "c.json"], cwd=d, capture_output=True,
                         text=True)
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", fit.stderr).group(1)
    wall = re.search(r"Elapsed \(wall clock\) time.*: (\S+)", fit.stderr).group(1)
    print(f"homocal fit --method least-change, {n:,} points: exit {fit.returncode}, peak RSS {int(rss) / 1024:.0f} MB, "
          f"wall {wall}; {fit.stdout.splitlines()[0][:120] if fit.stdout else fit.stderr.splitlines()[0]}")

    cv2.imwrite(str(d / "map.png"), np.zeros((1000, 800, 3), np.uint8))
    server = subprocess.Popen([sys.executable, "-m", "homocal.cli", "ui", "--frame", "map.png", "--site-map", "map.png",
                               "--scale", "10", "--origin", "400,600", "-o", "uiout"], cwd=d, stdout=subprocess.PIPE,
                              text=True)
    try:
        url, token = server.stdout.readline().split(" on ")[-1].split(" ")[0].split("?token=")
        before = peak_kb(server.pid)
        points = np.loadtxt(d / "ref.csv", delimiter=",", skiprows=1).tolist()
        body = json.dumps({"trapezoid": {"image": TRAP["image"], "map": TRAP["map"]}, "camera_origin": [0, 0],
                           "points": points, "method": "least-change"}).encode()
        start = time.perf_counter()
        request = urllib.request.Request(url + "api/fit", data=body, headers={"Content-Type": "application/json",
                                                                              "X-Homocal-Token": token})
        try:
            status = urllib.request.urlopen(request, timeout=600).status
        except urllib.error.HTTPError as e:
            status = e.code
        print(f"homocal ui POST /api/fit, {n:,} least-change points ({len(body) / 1e6:.1f} MB body): status {status} in "
              f"{time.perf_counter() - start:.1f} s; server peak RSS {before / 1024:.0f} MB before, "
              f"{peak_kb(server.pid) / 1024:.0f} MB after")
    finally:
        server.terminate()
        server.wait()


if __name__ == "__main__":
    main()
