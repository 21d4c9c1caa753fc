"""What every plugin kind shares: its kind, registered name and declared parameters.

The registry validates a plugin's parameters against ``params`` (:class:`~explore.core.params.Param`)
and builds it with them as keyword arguments; the default constructor stores each one as an
attribute of the same name.
"""

from __future__ import annotations

from typing import Any, ClassVar

from explore.core.params import Param


class Plugin:
    """Base of every plugin contract (sensor, robot, motion planner, view generator, ...).

    Class attributes
    ----------------
    kind : the plugin kind (one of ``explore.api.KINDS``); set by the contract class
    name : the registered name (``explore run --strategy NAME``, tree parameters, world files)
    params : the declared parameters, in the order ``explore plugins list --params`` shows them
    """

    kind: ClassVar[str] = ""
    name: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()

    def __init__(self, **values: Any) -> None:
        for key, value in values.items():
            setattr(self, key, value)
