"""A run's report images in object storage: where they live (`reports/<run id>/<name>.png`), how
the worker stores them, and how the API reads them back.

The worker writes the images before the result, so a run whose result exists has its images
(or a `report.error` in its result saying why not). A retried attempt overwrites them.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from typing import BinaryIO

from pipeline import REPORT_IMAGES
from service.storage import Storage, validate_key

REPORT_TITLES: Mapping[str, str] = {
    "map-top": "Map from above, before and after",
    "map-side": "Map from the side, before and after",
    "error": "Error per iteration",
}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def report_key(run_id: uuid.UUID | str, name: str) -> str:
    """The storage key of image `name` (one of `REPORT_IMAGES`) of run `run_id`."""
    if name not in REPORT_IMAGES:
        raise ValueError(f"no report image {name!r}; the images are {list(REPORT_IMAGES)}")
    return validate_key(f"reports/{uuid.UUID(str(run_id))}/{name}.png")


def store_report_images(
    storage: Storage, run_id: uuid.UUID | str, images: Mapping[str, bytes]
) -> list[str]:
    """Store each PNG of `images` under its key; the names stored, in `REPORT_IMAGES` order."""
    stored = []
    for name in REPORT_IMAGES:
        if name not in images:
            continue
        data = images[name]
        if not data.startswith(PNG_MAGIC):
            raise ValueError(f"report image {name!r} is not a PNG")
        upload = storage.begin_upload(report_key(run_id, name))
        try:
            upload.write(data)
            upload.commit()
        except BaseException:
            upload.abort()
            raise
        stored.append(name)
    return stored


def stored_report_images(storage: Storage, run_id: uuid.UUID | str) -> list[str]:
    """The names of the images stored for the run, in `REPORT_IMAGES` order."""
    return [name for name in REPORT_IMAGES if storage.exists(report_key(run_id, name))]


def open_report_image(storage: Storage, run_id: uuid.UUID | str, name: str) -> BinaryIO:
    return storage.open(report_key(run_id, name))
