"""Judge a `RecordingSummary`: the checks that make a recording unusable, and the warnings."""

from __future__ import annotations

import numpy as np

from pipeline.io.config import WarningThresholds
from pipeline.io.errors import EmptyStopCloudError, MissingExtrinsicsError
from pipeline.io.summary import RecordingSummary


def require_extrinsics(summary: RecordingSummary) -> None:
    """Raise `MissingExtrinsicsError` naming every LiDAR without an initial `T_base_lidar`."""
    missing = [lidar for lidar in summary.lidars if lidar.T_base_lidar is None]
    if not missing:
        return
    names = ", ".join(f"{lidar.frame} ({lidar.topic})" for lidar in missing)
    example = missing[0].frame
    raise MissingExtrinsicsError(
        f"{summary.path}: no initial extrinsics for {names}: /tf_static has no chain "
        f"{summary.base_frame} -> ... -> LiDAR frame. Record /tf_static (robot_state_publisher or "
        f"static_transform_publisher), or give them in the config, e.g. extrinsics: "
        f"{{{example}: {{translation: [x, y, z], rotation_xyzw: [x, y, z, w]}}}}"
    )


def require_stop_points(summary: RecordingSummary) -> None:
    """Raise `EmptyStopCloudError` if a LiDAR has no valid point in some stop, saying why."""
    for stop in summary.stops:
        for lidar in summary.lidars:
            cloud = stop.clouds.get(lidar.frame)
            if cloud is not None and cloud.valid_points > 0:
                continue
            if cloud is None or cloud.scans == 0:
                touching = 0 if cloud is None else cloud.scans_touching
                why = (
                    f"none of its scans lies wholly inside the stop ({touching} stamped in it, "
                    f"scan period {lidar.period_s:.3f} s, stop {stop.duration_s:.2f} s); "
                    "make the stops longer or check the LiDAR's stamps"
                )
            else:
                why = (
                    f"its {cloud.scans} scans there hold only NaN, infinite or zero points; "
                    "check that the LiDAR works and is not blocked"
                )
            raise EmptyStopCloudError(
                f"{summary.path}: LiDAR {lidar.frame} ({lidar.topic}) has no valid point in stop "
                f"{stop.index} ({stop.t_start:.2f}-{stop.t_end:.2f} s): {why}"
            )


def recording_warnings(summary: RecordingSummary, thresholds: WarningThresholds) -> tuple[str, ...]:
    """What a user should fix or know before uploading; none of it stops the reader."""
    warnings = list(summary.notes)
    for lidar in summary.lidars:
        if lidar.T_base_lidar is None:
            warnings.append(
                f"missing tf: no /tf_static chain {summary.base_frame} -> {lidar.frame}; the "
                "calibration refuses this recording unless its config gives that LiDAR's extrinsics"
            )
    if len(summary.stops) < thresholds.min_stops:
        warnings.append(
            f"too few stops: {len(summary.stops)} found, {thresholds.min_stops} or more "
            "recommended (the reference routine has 16); add stops in different headings"
        )
    if summary.stops:
        per_stop = {
            lidar.frame: sum(
                stop.clouds[lidar.frame].valid_points
                for stop in summary.stops
                if lidar.frame in stop.clouds
            )
            / len(summary.stops)
            for lidar in summary.lidars
        }
        median = float(np.median(list(per_stop.values())))
        for lidar in summary.lidars:
            mean = per_stop[lidar.frame]
            if (
                mean < thresholds.min_points_per_stop
                or mean < thresholds.min_relative_points * median
            ):
                warnings.append(
                    f"LiDAR {lidar.frame} ({lidar.topic}) sees almost nothing: {mean:.0f} valid "
                    f"points per stop (median over LiDARs {median:.0f}); check that it is "
                    "connected, unobstructed and looking at the floor"
                )
    warnings += stop_warnings(summary, thresholds)
    return tuple(warnings)


def stop_warnings(summary: RecordingSummary, thresholds: WarningThresholds) -> list[str]:
    """Short stops, and LiDARs with few scans in a stop: kept, but worth knowing about."""
    warnings = []
    stops = summary.stops
    short = [stop for stop in stops if stop.duration_s < thresholds.short_stop_s]
    if short:
        shortest = min(short, key=lambda stop: stop.duration_s)
        warnings.append(
            f"short stops: {len(short)} of {len(stops)} stops last under "
            f"{thresholds.short_stop_s:g} s (shortest: stop {shortest.index}, "
            f"{shortest.duration_s:.2f} s); they are kept, but their clouds hold fewer scans. If "
            "the calibration fails its precision checks, record longer stops"
        )
    for lidar in summary.lidars:
        scans = [
            (cloud.scans if (cloud := stop.clouds.get(lidar.frame)) else 0, stop.index)
            for stop in stops
        ]
        sparse = [entry for entry in scans if entry[0] < thresholds.min_scans_per_stop]
        if sparse:
            fewest, where = min(sparse)
            warnings.append(
                f"sparse stops: LiDAR {lidar.frame} ({lidar.topic}) has fewer than "
                f"{thresholds.min_scans_per_stop} scans in {len(sparse)} of {len(stops)} stops "
                f"(fewest: {fewest} in stop {where}, scan period {lidar.period_s:.3f} s); they "
                "are kept, but cover its field of view sparsely. Longer stops give denser clouds"
            )
    return warnings
