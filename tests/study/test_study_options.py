"""The study's options, declared once (homocal.study.options): declarations, round trips, refusals, presets."""
from __future__ import annotations

import argparse
import ast
import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from homocal.study.cli import add_study_options, params_from_args
from homocal.study.inputs import OPTIONS, StudyParams, descent_settings, preset_params
from homocal.study.options import PRESETS, OptionError, options_markdown
from homocal.study.perturb import ShiftSpec
from homocal.study.sweep import SWEEPABLE, _typed

ROOT = Path(__file__).parents[2]
# a value other than the default of every option, as StudyParams keeps it
OTHER = {"seed": 7, "n_variants": 12, "foot_source": "segmentation", "n_test": 300, "max_test_distance": 30.5,
         "test_lateral_max": 4.0, "horizon_shift": ShiftSpec.parse("normal:6:2"), "click_noise": 1.5, "metric": "range",
         "map_scale": 2.5, "image_width": 1920.0, "perturbation": "variant", "lens": "known",
         "descent": descent_settings(14.0)}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(exit_on_error=False)
    add_study_options(p)
    return p


def test_every_field_is_an_option_or_declared_internal():
    for f in fields(StudyParams):
        assert ("option" in f.metadata) != ("internal" in f.metadata), f.name
    assert set(OTHER) == set(OPTIONS)


@pytest.mark.parametrize("name", list(OPTIONS))
def test_each_flag_parses_back_to_the_same_value(name):
    """value -> the flag's text -> the flag parsed by homocal study's parser -> the same value, for a value other
    than the default and for none where the option takes none; and through study.json (to_dict / from_dict)."""
    opt = OPTIONS[name]
    for value in (OTHER[name], *((None,) if opt.none else ())):
        text = opt.to_text(value)
        assert opt.from_text(text) == value
        params = params_from_args(parser().parse_args([opt.flag, text]))
        assert getattr(params, name) == value
        assert getattr(StudyParams.from_dict(StudyParams(**{name: value}).to_dict()), name) == value


def test_study_json_holds_shift_text_and_the_params_hold_it_parsed():
    params = StudyParams(horizon_shift="uniform:-4:12")
    assert params.horizon_shift == ShiftSpec("uniform", -4.0, 12.0)
    assert params.to_dict()["horizon_shift"] == "uniform:-4:12"
    assert StudyParams(horizon_shift=6).horizon_shift == ShiftSpec("fixed", 6.0)


def test_sweep_takes_the_sweepable_options_by_their_flag_names():
    assert SWEEPABLE["descent_delta_max"] == "descent" and "n_variants" not in SWEEPABLE.values()
    assert _typed("descent_delta_max", "14") == descent_settings(14.0)
    assert _typed("horizon_shift", "none") is None and _typed("seed", "3") == 3


BAD = [("seed", -1), ("seed", 2**63), ("seed", 10**400), ("n_test", 10**400), ("n_variants", -10**400), ("seed", 1.5), ("seed", True), ("n_variants", 100_001), ("n_test", 0),
       ("foot_source", ""), ("foot_source", 3), ("max_test_distance", 0.0), ("max_test_distance", math.inf),
       ("test_lateral_max", math.nan), ("horizon_shift", "eight"), ("horizon_shift", "200"), ("horizon_shift", True),
       ("horizon_shift", "normal:6:-1"), ("click_noise", -1.0), ("click_noise", 1e308), ("click_noise", "1"),
       ("metric", "l1"), ("map_scale", True), ("map_scale", 2000.0), ("image_width", -1.0), ("perturbation", "each"),
       ("descent", descent_settings(0.0)), ("descent", 8.0), ("n_variants", None)]


@pytest.mark.parametrize("name, value", BAD)
def test_a_bad_value_names_the_parameter_not_the_flag(name, value):
    with pytest.raises(OptionError) as raised:
        StudyParams(**{name: value})
    message = str(raised.value)
    assert message.startswith(f"{name} ") and "--" not in message and "\n" not in message


@pytest.mark.parametrize("name, text", [
    ("seed", "-1"), ("seed", "1" + "0" * 400), ("n_variants", "1.5"), ("n_test", "9" * 400), ("n_test", "0"), ("foot_source", ""), ("max_test_distance", "inf"),
    ("test_lateral_max", "nan"), ("horizon_shift", "eight"), ("click_noise", "1e400"), ("metric", "l1"),
    ("map_scale", ""), ("image_width", "-1"), ("perturbation", "each"), ("descent", "0")])
def test_the_cli_names_the_flag(name, text):
    with pytest.raises(argparse.ArgumentError, match=f"argument {OPTIONS[name].flag}: expected .*, got {text!r}"):
        parser().parse_args([OPTIONS[name].flag, text])


def test_the_name_image_width_is_written_at_most_once_in_homocal():
    """Adding an option is one declaration: its name as a string literal appears at most once in homocal/."""
    count = 0
    for path in (ROOT / "homocal").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            count += isinstance(node, ast.Constant) and node.value == "image_width"
    assert count <= 1


def test_the_option_table_has_a_row_per_option_and_a_column_per_preset():
    table = options_markdown(StudyParams).splitlines()
    assert len(table) == 2 + len(OPTIONS)
    assert all(f"`--preset {p}`" in table[0] for p in PRESETS)
    row = next(line for line in table if line.startswith("| `--horizon-shift`"))
    assert row.split(" | ")[5:8] == ["`none`", "`none`", "`16`"]  # quick, paper, table1-fit


def test_the_presets_as_declared():
    """paper: the paper's protocol as it states it; table1-fit: the configuration fitted to Table 1."""
    paper, fit = preset_params("paper"), preset_params("table1-fit")
    assert (paper.horizon_shift, paper.perturbation, paper.map_scale, paper.metric) == (None, "coordinate", None, "range")
    assert paper.descent == StudyParams().descent and (paper.n_variants, paper.n_test) == (1000, 2000)
    assert (fit.horizon_shift, fit.perturbation, fit.map_scale, fit.metric) == (
        ShiftSpec("fixed", 16.0), "variant-positive", 1.5, "range")
    assert fit.descent == descent_settings(18.0) and (fit.n_variants, fit.n_test) == (1000, 2000)
    assert preset_params("quick") == StudyParams(n_variants=50)
    assert PRESETS["table1-fit"].label.startswith("fitted to Table 1") and "paper's protocol" in PRESETS["paper"].label
    help_text = parser().format_help()
    assert "table1-fit: fitted to Table 1, not the paper's protocol" in " ".join(help_text.split())


def test_the_paper_preset_states_how_far_the_hand_placed_corners_are():
    """The paper preset's help gives the distance of the hand-placed corners from the exact trapezoid's, measured
    here on both scenes from their configs (image px and map px, rounded to 0.1)."""
    scene_module = pytest.importorskip("simgen.scene")
    image, map_ = [], []
    for name in ("scene1", "scene2"):
        scene = scene_module.load_scene(ROOT / "scenes" / name)
        image += list(np.hypot(*(scene.hand_placed_image - scene.trapezoid_exact_image).T))
        map_ += list(np.hypot(*(scene.hand_placed_map - scene.trapezoid_exact_map).T))
    stated = (f"its image corners {min(image):.1f}-{max(image):.1f} px and its map corners "
              f"{min(map_):.1f}-{max(map_):.1f} map px from the exact trapezoid's")
    assert stated in PRESETS["paper"].details
    assert max(image) <= 3 and max(map_) <= 3  # within the paper's 0-3 px of careful placement
