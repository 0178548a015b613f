"""Render cost of a scene's people: wall and CPU milliseconds per frame of the RGB + segmentation passes.

    python benchmarks/bench_render.py [--scene scenes/scene1] [--frames 20] [--slices 28,16]

Frames 0.1 s apart from t = 3 s, seed 0; posing the agents is not timed. CPU time is the process's
(all of llvmpipe's threads), which a machine shared with other jobs disturbs far less than wall time.
``--slices N,M`` renders a copy of the scene with MuJoCo's capsule and sphere tessellation set to
N slices and M stacks (the shipped scenes use 16,8; MuJoCo's default is 28,16). The script uses only
``Stage(scene, seed, t_end)``, ``set_time``, ``rgb`` and ``agent_ids``, so it also runs on older
trees: ``git archive 93c2517 | tar -x -C /tmp/base`` then ``PYTHONPATH=/tmp/base python
benchmarks/bench_render.py --scene /tmp/base/scenes/scene1`` measures the rigid people before.
"""
from __future__ import annotations

import argparse
import re
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from simgen.scene import load_scene
from simgen.stage import Stage


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", type=Path, default=Path(__file__).resolve().parents[1] / "scenes" / "scene1")
    p.add_argument("--frames", type=int, default=20)
    p.add_argument("--slices", help="N,M: numslices and numstacks of a scene copy's <visual><quality>")
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = a.scene
        if a.slices:
            folder = Path(tmp) / a.scene.name
            shutil.copytree(a.scene, folder)
            xml = folder / "scene.xml"
            n, m = a.slices.split(",")
            text = re.sub(r'\s(numslices|numstacks)="\d+"', "", xml.read_text())  # the scene's <quality> element
            xml.write_text(text.replace("<quality ", f'<quality numslices="{n}" numstacks="{m}" ', 1))
        scene = load_scene(folder)
        wall, cpu = [], []
        with Stage(scene, seed=0, t_end=3.0 + a.frames * 0.1) as stage:
            q = stage.model.vis.quality
            for k in range(a.frames):
                stage.set_time(3.0 + k * 0.1)
                t0, c0 = time.perf_counter(), time.process_time()
                stage.rgb()
                stage.agent_ids()
                wall.append((time.perf_counter() - t0) * 1e3)
                cpu.append((time.process_time() - c0) * 1e3)
    print(f"{scene.name} {scene.camera.width}x{scene.camera.height}, {stage.model.ngeom} geoms, tessellation "
          f"{q.numslices}x{q.numstacks}: RGB + segmentation median {statistics.median(wall):.1f} ms/frame wall, "
          f"{statistics.median(cpu):.1f} ms/frame CPU ({a.frames} frames)")


if __name__ == "__main__":
    main()
