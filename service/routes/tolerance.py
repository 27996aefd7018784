"""Tolerance profiles: the pass/fail limits per robot model (admin writes, read keys read)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Response

from service import repository
from service.deps import AdminKey, ReadKey, SessionDep, WriteSessionDep
from service.models import ToleranceProfile
from service.problem_details import PROBLEM_RESPONSES, Conflict, ProfileNotFound
from service.schemas import (
    NAME_PATTERN,
    ToleranceProfileIn,
    ToleranceProfilePage,
    ToleranceProfilePublic,
)

router = APIRouter(
    prefix="/v1/tolerance-profiles", tags=["tolerance profiles"], responses=PROBLEM_RESPONSES
)

NamePath = Annotated[str, Path(pattern=NAME_PATTERN, description="The profile's name.")]


@router.get("", summary="Every tolerance profile, by name")
def list_profiles(_: ReadKey, session: SessionDep) -> ToleranceProfilePage:
    return ToleranceProfilePage(
        items=[profile_public(p) for p in repository.list_tolerance_profiles(session)]
    )


@router.get("/{name}", summary="One tolerance profile")
def get_profile(name: NamePath, _: ReadKey, session: SessionDep) -> ToleranceProfilePublic:
    profile = repository.get_tolerance_profile(session, name)
    if profile is None:
        raise ProfileNotFound(f"no tolerance profile {name!r}")
    return profile_public(profile)


@router.put(
    "/{name}",
    summary="Create or replace a tolerance profile (admin)",
    responses={201: {"description": "Created."}},
)
def put_profile(
    name: NamePath,
    body: ToleranceProfileIn,
    _: AdminKey,
    session: WriteSessionDep,
    response: Response,
) -> ToleranceProfilePublic:
    if body.robot_model is not None:
        other = repository.tolerance_profile_for_model(session, body.robot_model)
        if other is not None and other.name != name:
            raise Conflict(
                f"profile {other.name!r} already covers robot model "
                f"{body.robot_model!r}; change that one or clear its model first"
            )
    profile, created = repository.put_tolerance_profile(
        session,
        name,
        robot_model=body.robot_model,
        is_default=body.is_default,
        limits=body.limits.model_dump(exclude_none=True),
        design_extrinsics=None
        if body.design_extrinsics is None
        else {
            frame: pose.model_dump(mode="json") for frame, pose in body.design_extrinsics.items()
        },
    )
    session.commit()
    response.status_code = 201 if created else 200
    return profile_public(profile)


def profile_public(profile: ToleranceProfile) -> ToleranceProfilePublic:
    return ToleranceProfilePublic.model_validate(
        {
            "name": profile.name,
            "robot_model": profile.robot_model,
            "is_default": profile.is_default,
            "limits": profile.limits,
            "design_extrinsics": profile.design_extrinsics,
            "created_at": profile.created_at,
            "updated_at": profile.updated_at,
        }
    )
