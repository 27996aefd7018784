"""A run's report images (PNG, made by the worker): which exist, and each image's bytes."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from http import HTTPStatus
from typing import Annotated

from fastapi import APIRouter, Path
from fastapi.responses import StreamingResponse
from pydantic import BaseModel, Field
from sqlalchemy.orm import Session

from pipeline import REPORT_IMAGES
from service import repository
from service.auth import Principal
from service.deps import CurrentKey, ServicesDep, SessionDep
from service.models import Result, Run
from service.problem_details import PROBLEM_RESPONSES, ApiError, Forbidden, RunNotFound
from service.reports import REPORT_TITLES, open_report_image, report_key, stored_report_images

router = APIRouter(prefix="/v1/runs", tags=["reports"], responses=PROBLEM_RESPONSES)

_CHUNK = 256 * 1024


class ReportImageNotFoundError(ApiError):
    slug = "report-image-not-found"
    title = "No such report image"
    status = HTTPStatus.NOT_FOUND


class ReportImage(BaseModel):
    name: str = Field(examples=["map-top"])
    title: str
    url: str = Field(description="GET it with the same API key: a PNG image.")


class ReportIndex(BaseModel):
    run_id: uuid.UUID
    images: list[ReportImage] = Field(
        description="The images stored for the run (none before its worker has finished, or "
        "when the worker could not draw them: see the result's `report.error`)."
    )


ImageName = Annotated[
    str, Path(description=f"One of {', '.join(REPORT_IMAGES)}.", pattern=r"^[a-z-]+$")
]


@router.get("/{run_id}/report", summary="The run's report images")
def get_report(
    run_id: uuid.UUID, principal: CurrentKey, session: SessionDep, services: ServicesDep
) -> ReportIndex:
    readable_run(session, principal, run_id)
    return ReportIndex(
        run_id=run_id,
        images=[
            ReportImage(name=name, title=REPORT_TITLES[name], url=image_url(run_id, name))
            for name in stored_report_images(services.storage, run_id)
        ],
    )


@router.get(
    "/{run_id}/report/{name}.png",
    summary="One report image",
    response_class=StreamingResponse,
    responses={200: {"content": {"image/png": {}}, "description": "The PNG image."}},
)
def get_report_image(
    run_id: uuid.UUID,
    name: ImageName,
    principal: CurrentKey,
    session: SessionDep,
    services: ServicesDep,
) -> StreamingResponse:
    if name not in REPORT_IMAGES:
        raise ReportImageNotFoundError(
            f"no report image {name!r}; the images are {list(REPORT_IMAGES)}"
        )
    readable_run(session, principal, run_id)
    if not services.storage.exists(report_key(run_id, name)):
        raise ReportImageNotFoundError(f"run {run_id} has no {name} image (yet)")
    source = open_report_image(services.storage, run_id, name)

    def chunks() -> Iterator[bytes]:
        # Starlette iterates a plain iterator in its thread pool: reads never block the loop.
        with source:
            while data := source.read(_CHUNK):
                yield data

    return StreamingResponse(
        chunks(),
        media_type="image/png",
        # A run's images never change once its result exists; a retry happens before that.
        headers={"Cache-Control": "private, max-age=86400"},
    )


def image_url(run_id: uuid.UUID, name: str) -> str:
    return f"/v1/runs/{run_id}/report/{name}.png"


def readable_run(
    session: Session, principal: Principal, run_id: uuid.UUID
) -> tuple[Run, Result | None]:
    """The run and its result, if the key may read the run's robot (404 / 403 otherwise)."""
    found = repository.get_run(session, run_id)
    if found is None:
        raise RunNotFound(f"no run {run_id}")
    if not principal.may_read_robot(found[0].robot_id):
        raise Forbidden("this key may not read this robot's runs")
    return found
