"""The perception contracts: segmenter, recogniser, pose validator and registrar plugins."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from explore.core import Points3, Pose
from explore.core.plugin import Plugin

if TYPE_CHECKING:
    from explore.perception.database import Model
    from explore.perception.hypotheses import Hypothesis
    from explore.perception.segmentation import Cloud, Cluster, Segmentation, Table
    from explore.perception.validation import Validation
    from explore.sim import Scan


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


class PoseValidator(Plugin, ABC):
    """Contract of kind ``pose_validator``: does the PVS agree with a model at a pose?

    :meth:`validate` places ``model_vertices`` (n, 3, model frame, metres) at ``pose``
    (world_T_model) in the PVS and returns a :class:`~explore.perception.validation.Validation`
    (score v_h, vertex counts, accepted, margin to the threshold); Kriegel Eq. 3.11.
    """

    kind = "pose_validator"

    @abstractmethod
    def validate(self, pvs: Any, model_vertices: Points3, pose: Pose) -> Validation:
        """The PVS's verdict on the model at ``pose``."""

    def validate_hypothesis(self, hypothesis: Hypothesis, pvs: Any, model_vertices: Points3) -> Validation:
        """:meth:`validate` at the hypothesis' pose."""
        return self.validate(pvs, model_vertices, hypothesis.pose)


class Registrar(Plugin):
    """Contract of kind ``registrar``: corrected poses of scans.

    A registrar has one ``register`` method whose arguments follow its ``role``:
    ``"scan_to_model"`` (source points and normals, target points and normals, initial pose ->
    an :class:`~explore.perception.icp.IcpResult`, the thesis' local ICP), ``"plane"`` (source,
    target, the support plane in the target frame -> IcpResult, Görner's Plane ICP) or
    ``"scans"`` (a run's scans and believed world_T_sensor poses -> a
    :class:`~explore.perception.pose_graph.PoseGraphResult`). A session asks for a registrar of
    the role it needs.
    """

    kind = "registrar"
    role: str = "scan_to_model"

    def __init__(self, **values: Any) -> None:
        for param in self.params:
            setattr(self, param.name, values.get(param.name, param.default))
