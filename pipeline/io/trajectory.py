"""`Trajectory`: the recording's `T_odom_base` samples, sorted by time, as arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from pipeline.transforms import Matrix4, make_transform


@dataclass(frozen=True)
class Trajectory:
    """Poses of the base in the odometry frame.

    `stamps_ns`: (N,) int64, strictly increasing. `translations`: (N, 3) float64.
    `rotations_xyzw`: (N, 4) float64 unit quaternions `[x, y, z, w]`. `source` says where they
    came from (`odometry:/odom` or `tf:odom->base_link`), for messages and reports.
    """

    stamps_ns: NDArray[np.int64]
    translations: NDArray[np.float64]
    rotations_xyzw: NDArray[np.float64]
    source: str

    @classmethod
    def from_arrays(
        cls,
        stamps_ns: NDArray[np.int64],
        translations: NDArray[np.float64],
        rotations_xyzw: NDArray[np.float64],
        source: str,
    ) -> Trajectory:
        """Sort (N,) stamps, (N, 3) translations and (N, 4) quaternions by time.

        Of samples sharing a stamp the last wins; quaternions are normalised (they must be
        finite and non-zero: filter them first, see `valid_samples`).
        """
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        order = np.argsort(stamps, kind="stable")
        stamps = stamps[order]
        last_of_stamp = (
            np.r_[stamps[1:] != stamps[:-1], True] if len(stamps) else order.astype(bool)
        )
        keep = order[last_of_stamp]
        quats = np.asarray(rotations_xyzw, dtype=np.float64)[keep]
        quats = quats / np.linalg.norm(quats, axis=1, keepdims=True)
        translations = np.asarray(translations, dtype=np.float64)[keep]
        return cls(stamps[last_of_stamp], translations, quats, source)

    def __len__(self) -> int:
        return len(self.stamps_ns)

    @property
    def seconds(self) -> NDArray[np.float64]:
        return self.stamps_ns.astype(np.float64) * 1e-9

    @property
    def rotations(self) -> Rotation:
        return Rotation.from_quat(self.rotations_xyzw)

    def mean_pose(self, first: int, last: int) -> Matrix4:
        """Mean `T_odom_base` of samples `first..last` (inclusive): mean translation, rotation."""
        span = slice(first, last + 1)
        rotation = Rotation.from_quat(self.rotations_xyzw[span]).mean()
        return make_transform(rotation.as_matrix(), self.translations[span].mean(axis=0))


def valid_samples(
    translations: NDArray[np.float64], rotations_xyzw: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """(N,) mask of samples with a finite translation and a finite, non-zero quaternion."""
    norms = np.linalg.norm(rotations_xyzw, axis=1)
    valid: NDArray[np.bool_] = (
        np.isfinite(translations).all(axis=1) & np.isfinite(norms) & (norms > 1e-6)
    )
    return valid
