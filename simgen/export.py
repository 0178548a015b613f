"""``simgen export-mot``: a dataset as a MOTChallenge sequence folder, the layout TrackEval and motmetrics read.

    DIR/
      seqinfo.ini          [Sequence] name (the dataset's scene), frameRate, seqLength (frames_total), imWidth, imHeight
      gt/gt.txt            the ground truth in the MOT16/17 gt layout (as the dataset's mot/gt.txt)
      det/<detector>.txt   each detector's detections in the MOT17 det.txt layout (write_mot_det)
      export.json          marks DIR as an export (format "simgen-mot-export") and names what it came from

Pixel and frame conventions are the dataset's MOT ones (data_schema.md, mot/gt.txt). DIR is held with
``homocal.files.output_folder``: a new or empty folder, or an earlier export, whose files are then rewritten
(and the det files of detectors the dataset no longer has removed); any other folder is refused untouched.
"""
from __future__ import annotations

from pathlib import Path

import pyarrow.compute as pc
import pyarrow.parquet as pq

from homocal.names import check_name
from homocal.files import LOCK_NAME, OutputFolderError, json_format, output_folder, read_json, write_json_atomic, write_text_atomic
from simgen.detection.mot import write_mot_det, write_mot_gt

FORMAT = "simgen-mot-export"
MARKER = "export.json"


def export_mot(dataset_dir: str | Path, out: str | Path) -> dict[str, int]:
    """Write the MOTChallenge sequence folder ``out`` of the complete dataset ``dataset_dir`` (module docstring).

    Returns the line count of each file written under ``out`` (``gt/gt.txt``, ``det/<name>.txt``). Raises
    ValueError (the dataset: missing, incomplete, a scene or detector name that fails ``check_name``) or OutputFolderError
    (``out`` is not ours, or another run writes it), each one line, before anything is written.
    """
    dataset_dir, out = Path(dataset_dir), Path(out)
    manifest, camera = (_read_json(dataset_dir / name) for name in ("manifest.json", "camera.json"))
    if not manifest.get("complete"):
        raise ValueError(f"{dataset_dir}: the run is not complete; finish it with simgen generate --resume first")
    where, detectors = dataset_dir / "manifest.json", manifest.get("detectors")
    if not isinstance(detectors, list):
        raise ValueError(f"{where}: detectors: expected a list of names, got {detectors!r:.80}")
    check_name(manifest.get("scene"), f"{where}: scene")
    for name in detectors:
        check_name(name, f"{where}: detector")
    gt, detections = (pq.read_table(dataset_dir / name) for name in ("gt.parquet", "detections.parquet"))
    _check_ours(out)
    with output_folder(out, FORMAT, resume=True, marker=MARKER) as folder:
        files = ["seqinfo.ini", "gt/gt.txt", *(f"det/{name}.txt" for name in detectors)]
        previous = [f for f in (read_json(folder.marker).get("files", []) if folder.marker.is_file() else []) if _is_det_file(f)]
        folder.remove_temporaries([MARKER, *files, *previous])
        write_json_atomic(folder.marker, {"format": FORMAT, "dataset": str(dataset_dir.resolve()), "scene": manifest["scene"],
                                          "seed": manifest["seed"], "config_hash": manifest["config_hash"], "files": files})
        write_text_atomic(out / "seqinfo.ini", "[Sequence]\n" + "".join(f"{k}={v}\n" for k, v in {
            "name": manifest["scene"], "frameRate": manifest["fps"], "seqLength": manifest["frames_total"],
            "imWidth": camera["width"], "imHeight": camera["height"]}.items()))  # fmt: skip
        lines = {"gt/gt.txt": write_mot_gt(gt, manifest["fps"], out / "gt" / "gt.txt")}
        for name in detectors:
            rows = detections.filter(pc.equal(detections.column("detector"), name))
            lines[f"det/{name}.txt"] = write_mot_det(rows, out / "det" / f"{name}.txt")
        for stale in set(previous) - set(files):
            (out / stale).unlink(missing_ok=True)
    return lines


def _read_json(path: Path) -> dict:
    if not path.is_file():
        raise ValueError(f"{path.parent}: not a complete simgen dataset (no {path.name})")
    return read_json(path)


def _is_det_file(name: object) -> bool:
    """Whether an earlier export's marker names a det file this tool wrote (``det/<name>.txt``): the only stale
    files an export removes, whatever a hand-edited export.json lists."""
    return isinstance(name, str) and name.startswith("det/") and name.endswith(".txt") and Path(name).parent == Path("det")


def _check_ours(out: Path) -> None:
    """OutputFolderError unless ``out`` is missing, empty (a lock aside) or an earlier export."""
    if not out.is_dir() or {p.name for p in out.iterdir()} <= {LOCK_NAME}:
        return
    if json_format(out / MARKER) != FORMAT:
        raise OutputFolderError(f"{out}: exists and is not an export-mot folder (no {MARKER} with format {FORMAT!r}); nothing touched")
