"""`fleetcal denoise`: .npy and .ply round trips, options, and clean failures (exit 2)."""

from __future__ import annotations

from pathlib import Path
from typing import cast

import click
import numpy as np
import typer
from typer.testing import CliRunner, Result

from pipeline.cli import denoise as denoise_cli
from pipeline.denoise import DenoiseConfig, DenoiseMethod, denoise, dsor_mask
from tests.pipeline.denoise.clouds import floor_in_lidar_frame, veil

app = typer.Typer()
denoise_cli.register(app)
app.command("noop", hidden=True)(lambda: None)  # keeps `denoise` a named sub-command


def run(*args: str) -> Result:
    return CliRunner().invoke(app, ["denoise", *args])


def _cloud() -> np.ndarray:
    return np.vstack([floor_in_lidar_frame(5_000), veil(200)])


def test_npy_round_trip(tmp_path: Path) -> None:
    cloud = _cloud()
    source, mask_path = tmp_path / "cloud.npy", tmp_path / "mask.npy"
    np.save(source, cloud)

    result = run(str(source), "--output", str(mask_path), "--method", "dsor")

    assert result.exit_code == 0, result.output
    mask = np.load(mask_path)
    assert mask.dtype == np.bool_ and mask.shape == (len(cloud),)
    np.testing.assert_array_equal(mask, dsor_mask(cloud))
    assert f"dsor: removed {int((~mask).sum())} of {len(cloud)} points in " in result.output


def test_default_method_on_npy(tmp_path: Path) -> None:
    cloud = _cloud()
    source, mask_path = tmp_path / "cloud.npy", tmp_path / "mask.npy"
    np.save(source, cloud)

    result = run(str(source), "-o", str(mask_path))

    assert result.exit_code == 0, result.output
    np.testing.assert_array_equal(np.load(mask_path), denoise(cloud).keep)
    assert result.output.startswith(f"{DenoiseConfig().method}: removed ")


def test_ply_round_trip_with_another_axis_and_parameters(tmp_path: Path) -> None:
    import open3d as o3d

    cloud = _cloud()[:, [1, 2, 0]]  # the same scene with the optical axis along z
    source, mask_path = tmp_path / "cloud.ply", tmp_path / "mask.npy"
    o3d.io.write_point_cloud(source, o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud)))

    result = run(
        str(source), "-o", str(mask_path), "--method", "proposed", "--axis", "z",
        "--k", "10", "--cs", "0.5", "--cr", "2.0",
    )  # fmt: skip

    assert result.exit_code == 0, result.output
    config = DenoiseConfig(method=DenoiseMethod.PROPOSED, k=10, cs=0.5, cr=2.0)
    expected = denoise(cloud, config, optical_axis=(0.0, 0.0, 1.0)).keep
    np.testing.assert_array_equal(np.load(mask_path), expected)


def test_too_few_points_say_so(tmp_path: Path) -> None:
    source, mask_path = tmp_path / "cloud.npy", tmp_path / "mask.npy"
    np.save(source, _cloud()[:5])

    result = run(str(source), "-o", str(mask_path))

    assert result.exit_code == 0
    assert "note: 5 points are too few to judge with k=20; kept all" in result.output
    assert np.load(mask_path).all()


def test_bad_input_exits_2_with_a_message(tmp_path: Path) -> None:
    flat, text, nan = tmp_path / "flat.npy", tmp_path / "cloud.ply", tmp_path / "nan.npy"
    np.save(flat, np.zeros((10, 2)))
    text.write_text("not a ply file")
    np.save(nan, np.full((30, 3), np.nan))
    out = str(tmp_path / "mask.npy")

    cases = {
        "missing": (run(str(tmp_path / "nope.npy"), "-o", out), "no such file"),
        "shape": (run(str(flat), "-o", out), "expected (N, 3) x, y, z points"),
        "ply": (run(str(text), "-o", out), "open3d read no points"),
        "nan": (run(str(nan), "-o", out), "30 of 30 points have NaN or inf"),
        "suffix": (run(str(tmp_path), "-o", out), "no such file"),
        "option": (run(str(flat), "-o", out, "--k", "0"), "--k: Input should be greater"),
    }

    for name, (result, message) in cases.items():
        assert result.exit_code == 2, (name, result.output)
        assert result.output.startswith("error: ") and message in result.output, name
    assert not (tmp_path / "mask.npy").exists()


def test_an_unknown_format_and_an_unwritable_output_exit_2(tmp_path: Path) -> None:
    csv = tmp_path / "cloud.csv"
    csv.write_text("1,2,3\n")
    source = tmp_path / "cloud.npy"
    np.save(source, _cloud())

    unknown = run(str(csv), "-o", str(tmp_path / "m.npy"))
    unwritable = run(str(source), "-o", str(tmp_path / "no" / "m.npy"))

    assert unknown.exit_code == 2 and "unknown cloud format '.csv'" in unknown.output
    assert unwritable.exit_code == 2 and "cannot write the mask" in unwritable.output


def test_option_choices_and_defaults_are_the_configs() -> None:
    # The CLI spells them out so that `fleetcal` starts without numpy and pydantic; they must
    # still say what `DenoiseConfig` does.
    config = DenoiseConfig()
    root = cast(click.Group, typer.main.get_command(app))  # `app` has sub-commands: a group
    options = {param.name: param for param in root.commands["denoise"].params}

    assert [m.value for m in denoise_cli.Method] == [m.value for m in DenoiseMethod]
    assert [options[name].default for name in ("method", "k", "cs", "cr")] == [
        config.method.value,
        config.k,
        config.cs,
        config.cr,
    ]
