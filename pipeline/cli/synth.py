"""`fleetcal synth SCENARIO --out DIR`: write a synthetic recording and its ground truth.

`fleetcal synth random --seed N --out DIR` writes the randomised scenario the seed draws;
`--world room` (people, uneven-floor, dust, factory, open, or random: the seed draws one) puts
the same draw into that world.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from pipeline.cli.common import progress, user_errors

RANDOM = "random"


def register(app: typer.Typer) -> None:
    app.command("synth")(synth_command)


def synth_command(
    scenario: Annotated[
        str,
        typer.Argument(
            help="scenario name, e.g. set1-box, set2-capsule, spinning, tiny; or random (the "
            "seed draws the routine, LiDARs, objects and errors)"
        ),
    ],
    out: Annotated[
        Path, typer.Option("--out", help="output directory (must not exist or be empty)")
    ],
    seed: Annotated[int, typer.Option(help="random seed: same seed, same recording", min=0)] = 0,
    rate_scale: Annotated[
        float, typer.Option(help="multiplies every LiDAR's point rate (0.1 for quick tests)")
    ] = 1.0,
    ros1: Annotated[bool, typer.Option("--ros1", help="also write recording.bag (ROS 1)")] = False,
    world: Annotated[
        str | None,
        typer.Option(
            help="random only: open, room, people, uneven-floor, dust, factory, or random (the "
            "seed draws one); left out, the open floor as before worlds existed"
        ),
    ] = None,
) -> None:
    """Synthesise SCENARIO with MuJoCo into DIR/recording (ROS 2 bag, MCAP) plus truth.json.

    The recording follows the input contract (PointCloud2 per LiDAR, /odom, /tf_static with
    perturbed extrinsics); truth.json and labels.npz hold the true poses and noise labels.
    """
    from pipeline.errors import ConfigError
    from pipeline.synth.random_scenario import random_scenario
    from pipeline.synth.recording import write_recording
    from pipeline.synth.scenarios import get_scenario

    started = time.perf_counter()
    with user_errors():
        if world is not None and scenario != RANDOM:
            raise ConfigError(
                f"--world is for `fleetcal synth random`; {scenario!r} has its own world "
                "(the world scenarios are room, people, uneven-floor, dust and factory)"
            )
        spec = random_scenario(seed, world=world) if scenario == RANDOM else get_scenario(scenario)
        progress(f"synthesising {spec.name} (seed {seed}, rate x{rate_scale:g}) into {out}")
        if scenario == RANDOM:
            progress(f"{spec.name}: class {spec.scenario_class}; {spec.description}")
        write_recording(spec, out, seed=seed, rate_scale=rate_scale, ros1=ros1, progress=progress)
    progress(f"done in {time.perf_counter() - started:.1f} s: {out}")
    typer.echo(str(out))
