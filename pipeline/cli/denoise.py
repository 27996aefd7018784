"""`fleetcal denoise`: run stage 1 on one cloud file and write its keep mask.

The options' choices and defaults are literals, not read from `DenoiseConfig`: importing
`pipeline.denoise` loads numpy and pydantic, which every `fleetcal` start (even `--help`) would
then pay for. tests/pipeline/cli/test_denoise.py checks that they agree with the config.
"""

from __future__ import annotations

import enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from pipeline.cli.common import user_errors
from pipeline.errors import BadInputError, ConfigError

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray


class Method(enum.StrEnum):
    """The values of `pipeline.denoise.DenoiseMethod`, in its order."""

    PATTERN = "pattern"
    PROPOSED = "proposed"
    FLOORED = "floored"
    SOR = "sor"
    DSOR = "dsor"
    RANGE_GAP = "range_gap"


DEFAULT_METHOD = Method.PATTERN
DEFAULT_K = 20
DEFAULT_CS = 0.01
DEFAULT_CR = 3.0
"""`DenoiseConfig()`'s `method`, `k`, `cs` and `cr`."""


class Axis(enum.StrEnum):
    X = "x"
    Y = "y"
    Z = "z"


_AXIS_VECTORS = {Axis.X: (1.0, 0.0, 0.0), Axis.Y: (0.0, 1.0, 0.0), Axis.Z: (0.0, 0.0, 1.0)}


def register(app: typer.Typer) -> None:
    app.command("denoise")(denoise_command)


def denoise_command(
    input_path: Annotated[
        Path,
        typer.Argument(
            metavar="INPUT",
            help="(N, 3) .npy in the LiDAR frame (sensor at the origin), or a .pcd / .ply",
        ),
    ],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="where to write the (N,) bool mask, True = keep")
    ],
    method: Annotated[Method, typer.Option(help="which filter")] = DEFAULT_METHOD,
    k: Annotated[int, typer.Option(help="neighbours per point")] = DEFAULT_K,
    cs: Annotated[float, typer.Option(help="C_s: H_g = mu + sigma * C_s")] = DEFAULT_CS,
    cr: Annotated[float, typer.Option(help="C_r: dynamic threshold factor")] = DEFAULT_CR,
    axis: Annotated[Axis, typer.Option(help="the LiDAR's optical axis (Livox: x)")] = Axis.X,
) -> None:
    """Remove bleeding points from one LiDAR cloud (stage 1) and save which points to keep."""
    import numpy as np
    from pydantic import ValidationError

    from pipeline.denoise import DenoiseConfig, DenoiseMethod, denoise

    with user_errors():
        try:
            config = DenoiseConfig(method=DenoiseMethod(method.value), k=k, cs=cs, cr=cr)
        except ValidationError as err:
            problems = "; ".join(f"--{e['loc'][0]}: {e['msg']}" for e in err.errors())
            raise ConfigError(f"invalid option: {problems}") from None
        points = read_cloud(input_path)
        result = denoise(points, config, optical_axis=_AXIS_VECTORS[axis])
        try:
            with output.open("wb") as stream:
                np.save(stream, result.keep)
        except OSError as err:
            raise BadInputError(
                f"cannot write the mask to {output}: {err.strerror}; check the folder exists"
            ) from None
        typer.echo(
            f"{result.method}: removed {result.removed_points} of {len(points)} points "
            f"in {result.seconds:.3f} s -> {output}"
        )
        if result.note:
            typer.echo(f"note: {result.note}")


def read_cloud(path: Path) -> NDArray[np.float64]:
    """The (N, 3) points of a .npy, .pcd or .ply file; `BadInputError` if it cannot give them."""
    import numpy as np

    if not path.is_file():
        raise BadInputError(f"no such file: {path}")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            points = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as err:
            raise BadInputError(f"{path} is not a readable .npy array ({err})") from None
        if points.ndim != 2 or points.shape[1] != 3:
            raise BadInputError(
                f"{path} holds an array of shape {points.shape}; expected (N, 3) x, y, z points"
            )
        return np.asarray(points, dtype=np.float64)
    if suffix in (".pcd", ".ply"):
        import open3d as o3d

        cloud = o3d.io.read_point_cloud(path, format="auto", print_progress=False)
        points = np.asarray(cloud.points, dtype=np.float64)
        if len(points) == 0:
            raise BadInputError(f"open3d read no points from {path}; is it a valid {suffix} file?")
        return points
    raise BadInputError(f"{path}: unknown cloud format {suffix!r}; use .npy, .pcd or .ply")
