"""Routes for the behavioral map: manifolds, best grasps, pictures and exports.

The manifold table is read as stored: the keeper (manifolds/keeper.py) keeps it after each
committed batch, within a stated lag (the exploration's progress shows it), and no read
writes. `final` says whether the table is the completed exploration's.
"""

from __future__ import annotations

import json
import math
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Path, Query, Request, Response
from fastapi.responses import StreamingResponse
from graspscape.services.coordinator.api import answers
from graspscape.services.coordinator.api.deps import SessionDep
from graspscape.services.coordinator.api.finite import FiniteJSONRoute
from graspscape.services.coordinator.api.responses import encoded, error
from graspscape.services.coordinator.api.streams import ClosingStream
from graspscape.services.coordinator.errors import InvalidInput, NotFound
from graspscape.services.coordinator.exploration.schemas import PoseOut
from graspscape.services.coordinator.exploration.support import at_resting_pose
from graspscape.services.coordinator.manifolds import best as ranking
from graspscape.services.coordinator.manifolds import export, p_success
from graspscape.services.coordinator.manifolds import service as manifolds
from graspscape.services.coordinator.manifolds.p_success import SuccessOut
from graspscape.services.coordinator.manifolds.robust import coarser_for_error, error_in_steps
from graspscape.services.coordinator.manifolds.summary import (
    ManifoldSummary,
)
from graspscape.services.coordinator.manifolds.table import (
    ManifoldSuccess,
    manifold_successes,
    table_document,
)
from graspscape.services.coordinator.maps.stored import draw_finished_maps_ahead
from graspscape.services.coordinator.state import of
from pydantic import BaseModel, ConfigDict, Field

router = APIRouter(tags=["manifolds"], route_class=FiniteJSONRoute)
# The coordinator draws a finished map's default picture ahead, so that map.png's first read
# is a stored row, not a render (maps/stored.py, issue 21).
draw_finished_maps_ahead()

Id = Annotated[int, Path(ge=1, le=2**31 - 1, description="exploration id")]
_LABEL = r"^([A-Z]{1,3}|[0-9]{1,4})$"
Label = Annotated[str, Path(pattern=_LABEL, description="manifold label: A, B, … or 0, 1, …")]
_NOT_FOUND: dict[int | str, dict[str, Any]] = {404: error("no such exploration or manifold")}


class DustLine(BaseModel):
    """The manifolds under 1 % of the viable volume, as one entry."""

    manifolds: int
    poses: int
    volume_cm3: float


class ManifoldList(BaseModel):
    exploration_id: int
    final: bool = Field(description="true once the exploration completed")
    manifolds: list[ManifoldSummary]
    dust: DustLine | None = Field(default=None, description="the manifolds that are not "
                                  "`large` (under 1 % of the viable volume) as one entry")
    success: dict[str, ManifoldSuccess] = Field(
        default_factory=dict, description="by label, each large manifold's best grasp by "
        "rank=p_success with its k of n draws, bounds and claim (a manifold whose best has "
        "no certified claim says so with certified false)")


class ManifoldTable(ManifoldList):
    """On a table, also `resting_pose`: the object frame in the table frame (4×4 and
    position + quaternion), the pose's rank and probability, the table's friction."""

    model_config = ConfigDict(extra="allow")

    table: list[dict[str, Any]] = Field(description="one short row per large manifold (the "
                                        "docs' table: label, description, poses, volume, core "
                                        "volume, μs, best and robust best), then the dust as "
                                        "one row")


class CertificationEvidence(BaseModel):
    """What backs a pose's robust score (manifolds.best.Evidence)."""

    neighbours: int = Field(description="members of N_δ(p) on the lattice")
    neighbours_known: int = Field(description="of them stored (evaluated or shortcut-inferred)")
    neighbours_evaluated: int = Field(description="of them simulated by a worker")
    neighbours_held: int = Field(description="of them held with the pose's grasp type")
    certifying: int = Field(description="poses evaluated for this pose's certification "
                            "(their `certifies` is its key)")
    certifying_held: int = Field(description="of them held")


class BestPose(PoseOut):
    """A stored pose with its robust score at the δ of the request."""

    robust_s: float | None = Field(default=None, description="robust success s_δ: share of "
                                   "N_δ ∪ {p} held with the pose's grasp type (known members)")
    robust_s_low: float | None = Field(default=None, description="s_δ with unknown members "
                                       "counted as failures")
    robust_s_high: float | None = Field(default=None, description="… as successes")
    robust_q: float | None = Field(default=None, description="robust quality q_δ: mean μs over "
                                   "N_δ ∪ {p}, 0 for drops and other grasp types")
    robust_label: str | None = Field(default=None, description="robust (s ≥ 0.9), fragile, "
                                     "futile (s ≤ 0.1), or uncertain where the unknown members "
                                     "could change the label; null off the lattice")
    evidence: CertificationEvidence
    success: SuccessOut | None = Field(
        default=None, description="P(success) under the exploration's uncertainty model: k of "
        "n draws, the anytime-valid 95 % bounds and the claim; null where nothing was drawn")


class BestOut(BaseModel):
    exploration_id: int
    manifold: str | None
    rank: str = Field(description="what ranked the poses")
    delta_steps: int = Field(description="δ in finest lattice steps: 1, or 2 where the stated "
                             "pose error exceeds one step")
    delta_deg: float = Field(description="δ as an angle between approach directions, °")
    delta_mm: float = Field(description="δ along r, mm")
    error_within_delta: bool = Field(description="the stated pose error is within δ")
    uncertainty: dict[str, Any] = Field(
        default_factory=dict, description="the uncertainty model P(success) is stated under")
    level: float = Field(default=0.9, description="certified: lower bound ≥ this at 95 %")
    engines: list[str] | None = Field(
        default=None, description="the engines asked for: every pose's draws held with its "
        "grasp type in each of them (null: not asked)")
    poses: list[BestPose]


def _label_number(label: str) -> int:
    if label.isdigit():
        return int(label)
    n = 0
    for ch in label:
        n = n * 26 + (ord(ch) - ord("A") + 1)
    return n - 1


def _json(content: bytes) -> Response:
    return Response(content=content, media_type="application/json")


@router.get("/explorations/{exploration_id}/manifolds", response_model=ManifoldList,
            responses=_NOT_FOUND, summary="The behavioral manifolds, largest first")
def list_manifolds(exploration_id: Id, session: SessionDep, request: Request) -> Any:
    key = (answers.version(session, exploration_id), "manifolds")
    return _json(answers.answer(key, lambda: _manifolds_body(session, exploration_id),
                                of(request.app).answers))


def _manifolds_body(session: Any, exploration_id: int) -> bytes:
    # The summaries' stored JSON text copied into the answer, the dust line from columns:
    # nothing decoded, validated or encoded again (issue 21; migration 0012).
    final, items = manifolds.stored_texts(session, exploration_id)
    small = [m for m in items if not m.large]
    dust = (DustLine(manifolds=len(small), poses=sum(m.size for m in small),
                     volume_cm3=round(sum(m.volume_cm3 for m in small), 3)).model_dump()
            if small else None)
    head = json.dumps({"exploration_id": exploration_id, "final": final})[:-1]
    success = manifold_successes(session, exploration_id, [m.label for m in items if m.large])
    tail = json.dumps({k: v.model_dump(mode="json") for k, v in success.items()})
    return (f'{head}, "manifolds": [{", ".join(m.summary for m in items)}], '
            f'"dust": {json.dumps(dust)}, "success": {tail}}}'.encode())


@router.get("/explorations/{exploration_id}/manifolds/{label}", response_model=ManifoldSummary,
            responses=_NOT_FOUND, summary="One manifold by its label")
def get_manifold(exploration_id: Id, label: Label, session: SessionDep,
                 request: Request) -> Any:
    number = _label_number(label)

    def body() -> bytes:
        _, items = manifolds.stored_texts(session, exploration_id, number)
        if not items:  # raised, so never kept: a later refresh may add the label
            raise NotFound(f"exploration {exploration_id} has no manifold {label}")
        return items[0].summary.encode()

    key = (answers.version(session, exploration_id), "manifold", number)
    return _json(answers.answer(key, body, of(request.app).answers))


@router.get(
    "/explorations/{exploration_id}/best",
    response_model=BestOut,
    responses={**_NOT_FOUND, 422: {"description": "inconsistent constraints"}},
    summary="The best grasps (by μs, or another metric with rank=), overall or in one "
    "manifold, under constraints",
)
def best(
    exploration_id: Id,
    session: SessionDep,
    request: Request,
    manifold: Annotated[str | None, Query(pattern=_LABEL)] = None,
    cone_x: Annotated[float | None, Query(allow_inf_nan=False, ge=-1e6, le=1e6,
                                          description="approach-cone axis (object frame)")] = None,
    cone_y: Annotated[float | None, Query(allow_inf_nan=False, ge=-1e6, le=1e6)] = None,
    cone_z: Annotated[float | None, Query(allow_inf_nan=False, ge=-1e6, le=1e6)] = None,
    cone_half_angle_deg: Annotated[float | None, Query(ge=0.0, le=180.0,
                                                       allow_inf_nan=False)] = None,
    max_effort_nm: Annotated[float | None, Query(ge=0.0, le=1e6, allow_inf_nan=False)] = None,
    limit: Annotated[int, Query(ge=1, le=100)] = 1,
    rank: Annotated[ranking.Rank, Query(
        description="p_success (default): by the 95 % lower bound of P(success) under the "
        "exploration's uncertainty model, poses with draws first; robust: by the robust map "
        "over the pose-error neighbourhood N_δ — robust poses first, then uncertain, fragile, "
        "futile, each by robust quality q_δ; point: by the pose's own torque_margin_ratio; "
        "or by μs, a static metric (mu_g, mu_f, mu_m) or a robustness margin or test; highest "
        "first, except torque_margin_nm and friction_margin (lowest first); poses without the "
        "value come last, ties by μs"
    )] = ranking.BEST_DEFAULT_RANK,
    pose_error_mm: Annotated[float | None, Query(
        ge=0.0, le=1e4, allow_inf_nan=False,
        description="the robot's position error, mm: beyond one finest r step, δ is two "
        "steps")] = None,
    pose_error_deg: Annotated[float | None, Query(
        ge=0.0, le=180.0, allow_inf_nan=False,
        description="the robot's angular error, °: beyond one finest angular step, δ is two "
        "steps")] = None,
    resting: Annotated[int | None, Query(
        ge=0, le=1000,
        description="on a table: the best of the exploration of this one's group at resting "
        "pose `resting` (0: the most probable; GET /explorations/{id}/group lists them)",
    )] = None,
    engines: Annotated[str | None, Query(
        pattern=r"^(pybullet|mujoco)(,(pybullet|mujoco))?$",
        description="comma-separated engines, e.g. pybullet,mujoco: only grasps whose draws "
        "were simulated and held with their grasp type in each, ranked by P(success)")] = None,
) -> Any:
    if resting is not None:
        exploration_id = at_resting_pose(session, exploration_id, resting)
    axis_given = [c is not None for c in (cone_x, cone_y, cone_z)]
    axis = None
    if any(axis_given):
        if not all(axis_given) or cone_half_angle_deg is None:
            raise InvalidInput("a cone needs cone_x, cone_y, cone_z and cone_half_angle_deg",
                               loc=("query",))
        axis = (float(cone_x), float(cone_y), float(cone_z))  # type: ignore[arg-type]
        if math.hypot(*axis) < 1e-12:
            raise InvalidInput("the cone axis must not be zero", loc=("query", "cone_x"))
    elif cone_half_angle_deg is not None:
        raise InvalidInput("cone_half_angle_deg needs cone_x, cone_y, cone_z", loc=("query",))
    asked = tuple(sorted(set(engines.split(",")))) if engines else None
    # Every parameter is in the key (normalised as the computation reads them): the same
    # question at the same map version has the same answer (api/answers.py).
    key = (answers.version(session, exploration_id), "best", manifold, axis,
           cone_half_angle_deg, max_effort_nm, limit, ranking.Rank(rank).value,
           pose_error_mm, pose_error_deg, asked)
    return _json(answers.answer(key, lambda: _best_body(
        session, exploration_id, manifold=manifold, axis=axis,
        cone_half_angle_deg=cone_half_angle_deg, max_effort_nm=max_effort_nm, limit=limit,
        rank=rank, pose_error_mm=pose_error_mm, pose_error_deg=pose_error_deg,
        engines=asked), of(request.app).answers))


def _best_body(session: Any, exploration_id: int, *, manifold: str | None,
               axis: tuple[float, float, float] | None, cone_half_angle_deg: float | None,
               max_effort_nm: float | None, limit: int, rank: ranking.Rank,
               pose_error_mm: float | None, pose_error_deg: float | None,
               engines: tuple[str, ...] | None = None) -> bytes:
    """/best's answer as JSON bytes: validated once here (BestOut), encoded as FastAPI encodes
    a response model, so the route returns it as it is, not validated and encoded again."""
    lattice = ranking.lattice_of_exploration(session, exploration_id)
    coarser = coarser_for_error(lattice, pose_error_mm, pose_error_deg)
    rows = ranking.best_poses(
        session, exploration_id,
        label=_label_number(manifold) if manifold is not None else None,
        cone_axis=axis,
        cone_half_angle=math.radians(cone_half_angle_deg) if cone_half_angle_deg is not None
        else None,
        max_effort_nm=max_effort_nm, limit=limit, rank=rank, coarser=coarser,
        engines=engines,
    )
    evidence = ranking.robust_evidence(session, exploration_id, rows, coarser=coarser,
                                       lattice=lattice)
    chances = p_success.estimates(session, exploration_id, [r.pose_key for r in rows])
    model, level = p_success.model_of(session, exploration_id)
    poses = []
    for row, ev in zip(rows, evidence, strict=True):
        sc = ev.score
        stored = PoseOut.model_validate(row).model_dump()
        # The scores at the δ of the request, not the stored ones of the finest step.
        stored.update(robust_s=sc.s if sc else None, robust_q=sc.q if sc else None,
                      robust_label=sc.label.value if sc else None)
        poses.append(BestPose(
            **stored,
            robust_s_low=sc.s_low if sc else None, robust_s_high=sc.s_high if sc else None,
            evidence=CertificationEvidence(
                neighbours=ev.neighbours, neighbours_known=ev.neighbours_known,
                neighbours_evaluated=ev.neighbours_evaluated,
                neighbours_held=ev.neighbours_held, certifying=ev.certifying,
                certifying_held=ev.certifying_held),
            success=chances.get(row.pose_key),
        ))
    steps = 1 << coarser
    out = BestOut(
        exploration_id=exploration_id, manifold=manifold,
        rank=(ranking.Rank.P_SUCCESS if engines else ranking.DEFAULT_RANK
              if rank == ranking.Rank.POINT else rank).value,
        delta_steps=steps,
        delta_deg=math.degrees(lattice.dtheta(lattice.depth)) * steps,
        delta_mm=lattice.dr(lattice.depth) * 1000.0 * steps,
        error_within_delta=error_in_steps(lattice, pose_error_mm, pose_error_deg)
        <= steps + 1e-9,
        uncertainty=model.model_dump(mode="json"), level=level,
        engines=list(engines) if engines else None, poses=poses,
    )
    return encoded(out)


def _picture(exploration_id: int, session: Any, fmt: Literal["png", "svg"], cut: str,
             phi0_deg: float, attitude: int, r_mm: float | None = None) -> Response:
    from graspscape.services.coordinator.maps.picture import picture_bytes

    data, _, _ = picture_bytes(session, exploration_id, fmt, cut=cut,  # type: ignore[arg-type]
                               phi0_deg=phi0_deg, attitude=attitude, r_mm=r_mm,
                               title=f"exploration {exploration_id}")
    media = "image/png" if fmt == "png" else "image/svg+xml"
    return Response(content=data, media_type=media)


_PICTURE_RESPONSES: dict[int | str, dict[str, Any]] = {
    **_NOT_FOUND,
    200: {"content": {"image/png": {}, "image/svg+xml": {}}, "description": "the map"},
}
Cut = Annotated[Literal["horizontal", "vertical"], Query(description="plane of the cut")]
Phi0 = Annotated[float, Query(ge=-360.0, le=360.0, allow_inf_nan=False,
                              description="azimuth of a vertical cut, °")]
AttitudeQ = Annotated[int, Query(ge=0, le=1000, description="attitude index of the cut")]
RMm = Annotated[float | None, Query(ge=-1e6, le=1e6, allow_inf_nan=False,
                                    description="draw only the cut's band at this r, mm "
                                    "(nearest level of the finest lattice; 422 outside the "
                                    "grid's r range); default: every r")]


@router.get("/explorations/{exploration_id}/map.png", response_class=Response,
            responses=_PICTURE_RESPONSES, summary="The behavioral map (cut and 3D view), PNG")
def map_png(exploration_id: Id, session: SessionDep, cut: Cut = "horizontal", phi0_deg: Phi0 = 0.0,
            attitude: AttitudeQ = 0, r_mm: RMm = None) -> Response:
    return _picture(exploration_id, session, "png", cut, phi0_deg, attitude, r_mm)


@router.get("/explorations/{exploration_id}/map.svg", response_class=Response,
            responses=_PICTURE_RESPONSES, summary="The behavioral map (cut and 3D view), SVG")
def map_svg(exploration_id: Id, session: SessionDep, cut: Cut = "horizontal", phi0_deg: Phi0 = 0.0,
            attitude: AttitudeQ = 0, r_mm: RMm = None) -> Response:
    return _picture(exploration_id, session, "svg", cut, phi0_deg, attitude, r_mm)


def _stream_poses(exploration_id: int, request: Request, session: Any,
                  fmt: export.PoseFormat) -> StreamingResponse:
    """Every pose, streamed chunk by chunk from a server-side cursor, in a session of its own
    (export.session_pieces; the request's is closed here: FastAPI closes it only after the
    body is sent, so each stream held two connections). The stream stops, and gives its
    connection back, when the client goes away (api/streams.py)."""
    manifolds.require(session, exploration_id)
    session.close()
    pieces = export.session_pieces(request.app.state.sessionmaker, exploration_id, fmt)
    return ClosingStream(pieces, what=f"poses.{fmt} of exploration {exploration_id}",
                         media_type=export.MEDIA_TYPES[fmt])


@router.get("/explorations/{exploration_id}/export/poses.csv", response_class=StreamingResponse,
            responses={**_NOT_FOUND, 200: {"content": {"text/csv": {}}, "description": "CSV"}},
            summary="Every pose with its outcome, μs and manifold, CSV")
def export_csv(exploration_id: Id, request: Request, session: SessionDep) -> StreamingResponse:
    return _stream_poses(exploration_id, request, session, "csv")


@router.get(
    "/explorations/{exploration_id}/export/poses.parquet",
    response_class=StreamingResponse,
    responses={**_NOT_FOUND,
               200: {"content": {"application/vnd.apache.parquet": {}}, "description": "Parquet"}},
    summary="Every pose with its outcome, μs and manifold, Parquet",
)
def export_parquet(exploration_id: Id, request: Request, session: SessionDep) -> StreamingResponse:
    return _stream_poses(exploration_id, request, session, "parquet")


@router.get("/explorations/{exploration_id}/export/manifolds.json",
            response_model=ManifoldTable, responses=_NOT_FOUND,
            summary="The manifold table (summaries and short rows), JSON")
def export_manifolds(exploration_id: Id, session: SessionDep) -> Any:
    return table_document(session, exploration_id)
