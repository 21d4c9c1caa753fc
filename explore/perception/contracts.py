"""The perception contracts: segmenter, recogniser, pose validator and registrar plugins."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

from explore.core import BadInput, Points3, Pose
from explore.core.plugin import Plugin

if TYPE_CHECKING:
    from explore.perception.database import Model
    from explore.perception.depth_filters import DepthProcessing
    from explore.perception.hypotheses import Hypothesis
    from explore.perception.icp import IcpResult
    from explore.perception.incremental_graph import IncrementalPoseGraph
    from explore.perception.pose_graph import PoseGraphResult
    from explore.perception.segmentation import Cloud, Cluster, Segmentation, Table
    from explore.perception.validation import Validation
    from explore.sim import RaySensor, Scan


class Segmenter(Plugin, ABC):
    """Contract of kind ``segmenter``: a scene's points into a support table and object clusters.

    :meth:`segment` takes one or several :class:`~explore.sim.scan.Scan` objects (world-frame
    points, metres; fused) or a :class:`~explore.perception.segmentation.Cloud`, the view ids of
    the scans, and the table found so far; it returns a
    :class:`~explore.perception.segmentation.Segmentation` (table or None, clusters with the
    view each point came from, diagnostics).
    """

    kind = "segmenter"

    @abstractmethod
    def segment(self, scans: Scan | Sequence[Scan] | Cloud, view_ids: Sequence[int] | None = None,
                table: Table | None = None) -> Segmentation:
        """The table and the object clusters of ``scans``."""


class Recognizer(Plugin, ABC):
    """Contract of kind ``recognizer``: which known models a cluster is, and where.

    :meth:`recognize` returns :class:`~explore.perception.hypotheses.Hypothesis` objects (model
    name, world_T_model 4x4, quality in [0, 1], method, diagnostics), best first; ``scans`` are
    the views the cluster was seen in (by view id), for render-and-compare verification.
    """

    kind = "recognizer"

    @abstractmethod
    def recognize(self, cluster: Cluster, models: Sequence[Model],
                  scans: Mapping[int, Scan] | Sequence[Scan] | None = None) -> list[Hypothesis]:
        """Hypotheses for ``cluster`` over ``models``, best first (empty: not recognised)."""

    @abstractmethod
    def accept(self, hypotheses: Sequence[Hypothesis]) -> list[Hypothesis]:
        """The hypotheses good enough to be validated against the PVS."""

    def sense_with(self, sensor: RaySensor, processing: DepthProcessing) -> None:
        """The sensor the clusters come from and the processing of its views, given before the first
        :meth:`recognize`, so that a recogniser that renders training views of its models renders
        them as that sensor sees them. Default: nothing."""


class PoseValidator(Plugin, ABC):
    """Contract of kind ``pose_validator``: does the PVS agree with a model at a pose?

    :meth:`validate` places ``model_vertices`` (n, 3, model frame, metres; the scene passes the
    mesh's vertices, and samples on its large faces if it is coarse:
    :func:`~explore.perception.vote_points`) at ``pose`` (world_T_model) in the PVS and returns a
    :class:`~explore.perception.validation.Validation` (score v_h, vertex counts, accepted, margin
    to the threshold); Kriegel Eq. 3.11.
    """

    kind = "pose_validator"

    @abstractmethod
    def validate(self, pvs: Any, model_vertices: Points3, pose: Pose) -> Validation:
        """The PVS's verdict on the model at ``pose``."""

    def validate_hypothesis(self, hypothesis: Hypothesis, pvs: Any, model_vertices: Points3) -> Validation:
        """:meth:`validate` at the hypothesis' pose."""
        return self.validate(pvs, model_vertices, hypothesis.pose)


class Registrar(Plugin):
    """Contract of kind ``registrar``: corrected poses. A registrar subclasses the contract of its
    ``role``, which fixes what :meth:`register` takes and returns, and a session asks the registry
    for a registrar of the role it needs (:func:`require_role` refuses one of another role):

    - :class:`ScanToModelRegistrar` (``"scan_to_model"``): a scan's points to the model (thesis' local ICP);
    - :class:`PlaneRegistrar` (``"plane"``): a view to another over a shared support plane (Görner's Plane ICP);
    - :class:`ScansRegistrar` (``"scans"``): a run's scans and believed poses to corrected poses (pose graph).
    """

    kind = "registrar"
    role: ClassVar[str] = ""

    def __init__(self, **values: Any) -> None:
        for param in self.params:
            setattr(self, param.name, values.get(param.name, param.default))


class ScanToModelRegistrar(Registrar, ABC):
    """Registrar of role ``scan_to_model``: aligns a new scan with the model built so far."""

    role = "scan_to_model"

    @abstractmethod
    def register(self, source_points: Points3, source_normals: Points3 | None, target_points: Points3,
                 target_normals: Points3 | None, init: Pose | None = None) -> IcpResult:
        """The transform of the source into the target frame: source (n, 3) and target (m, 3) points
        in metres, unit normals or None, ``init`` a 4x4 first guess; the result holds the 4x4
        transform, its fitness (share of source points with a correspondence) and RMSE."""


class PlaneRegistrar(Registrar, ABC):
    """Registrar of role ``plane``: aligns two views of objects standing on the same plane."""

    role = "plane"

    @abstractmethod
    def register(self, source: Points3, target: Points3, plane: Any, source_plane: Any | None = None,
                 init: Pose | None = None) -> IcpResult:
        """Transform of ``source`` (n, 3) into the frame of ``target`` (m, 3); ``plane`` is the support
        plane (a, b, c, d with unit normal) in the target frame, ``source_plane`` in the source's."""


class ScansRegistrar(Registrar, ABC):
    """Registrar of role ``scans``: a run's views, each at its believed pose, to corrected poses."""

    role = "scans"

    @abstractmethod
    def register(self, scans: Sequence[Scan], poses: Sequence[Pose] | None = None) -> PoseGraphResult:
        """Corrected world_T_sensor (4x4) of every scan; ``poses`` are the believed ones (default:
        each scan's own), the result also holds the marginal covariances and the edges used."""

    @abstractmethod
    def incremental(self, plane: Any | None = None, reference: Points3 | None = None) -> IncrementalPoseGraph:
        """An empty graph with these parameters that grows one scan at a time; ``plane`` (the floor of
        a mobile base) restricts its edges to x, y, yaw, ``reference`` (points of the known
        environment, world frame) localises every scan in that map as well."""


def require_role(registrar: Registrar, role: str, where: str = "<run>") -> Registrar:
    """``registrar`` if it has ``role``; otherwise one line saying which role the step needs."""
    if getattr(registrar, "role", None) != role:
        raise BadInput(where, "registrar", f"{getattr(registrar, 'name', registrar)!r} has role "
                       f"{getattr(registrar, 'role', None)!r}; this step needs a registrar of role {role!r}")
    return registrar
