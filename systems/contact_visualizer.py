"""Contact forces drawn in Meshcat, from a
:class:`~drake_abs.systems.ComplementarityPlant`'s ``contact_results`` port: the counterpart of
Drake's ``ContactVisualizer`` (``pydrake.multibody.meshcat``), which only reads Drake's
``ContactResults``, a type pydrake cannot fill from Python (see
:mod:`drake_abs.multibody.contact_results`).
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.geometry import Cylinder, Meshcat, MeshcatCone
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.meshcat import ContactVisualizerParams
from pydrake.systems.framework import DiagramBuilder, EventStatus, LeafSystem_, OutputPort
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.multibody.contact_results import PointContactResults


@TemplateSystem.define("ContactForceVisualizer_", T_list=[float, AutoDiffXd])
def ContactForceVisualizer_(T):
    class Impl(LeafSystem_[T]):
        """Draws each point contact of a
        :class:`~drake_abs.multibody.contact_results.PointContactResults` input in Meshcat as
        Drake's ``ContactVisualizer`` draws a point contact: a double arrow (cylinder and two
        cones, ``params.color``) through the contact point along the force, ``|f| /
        params.newtons_per_meter`` (m) each way (the force on B and its opposite on A), hidden
        below ``params.force_threshold`` (N). It publishes every ``params.publish_period``
        seconds and on a forced publish; on initialization it deletes ``params.prefix`` when
        ``params.delete_on_initialization_event``. Hydroelastic settings are unused.

        .. pydrake_system::

            name: ContactForceVisualizer
            input_ports:
            - contact_results

        Each contact is drawn at ``/drake/<prefix>/point/<body A>+<body B>/<candidate>``
        (the bodies' names in the results' plant, the stepper's candidate index), so that
        several contacts between two bodies are each drawn (Drake's draws one per body pair).

        Args:
            meshcat: where to draw.
            params: Drake's ``ContactVisualizerParams`` (default: its defaults).
        """

        def _construct(
            self,
            meshcat: Meshcat,
            params: ContactVisualizerParams | None = None,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            if not isinstance(meshcat, Meshcat):
                raise ValueError(
                    f"ContactForceVisualizer: meshcat must be a Meshcat; got "
                    f"{type(meshcat).__name__}"
                )
            params = ContactVisualizerParams() if params is None else params
            if not isinstance(params, ContactVisualizerParams):
                raise ValueError(
                    "ContactForceVisualizer: params must be a ContactVisualizerParams; got "
                    f"{type(params).__name__}"
                )
            if not (params.publish_period > 0 and params.newtons_per_meter > 0):
                raise ValueError(
                    "ContactForceVisualizer: params.publish_period and "
                    "params.newtons_per_meter must be > 0; got "
                    f"{params.publish_period} and {params.newtons_per_meter}"
                )
            self.meshcat, self.params = meshcat, params
            #: what the last publish drew: ``{path: (p_WC (3,), f_Bc_W (3,))}`` of the shown
            #: contacts (m, N)
            self.drawn: dict[str, tuple[np.ndarray, np.ndarray]] = {}
            self._visible: dict[str, bool] = {}
            self.contact_results_port = self.DeclareAbstractInputPort(
                "contact_results", AbstractValue.Make(PointContactResults())
            )
            self.DeclarePeriodicPublishEvent(params.publish_period, 0.0, self._Publish)
            self.DeclareForcedPublishEvent(self._Publish)
            if params.delete_on_initialization_event:
                self.DeclareInitializationPublishEvent(self._Delete)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.meshcat, other.params, converter=converter)

        def contact_results_input_port(self):
            """The ``contact_results`` input (``ContactVisualizer``'s name for it)."""
            return self.contact_results_port

        def Delete(self) -> None:
            """Remove everything drawn (``params.prefix``) from Meshcat."""
            self.meshcat.Delete(self.params.prefix)
            self._visible.clear()
            self.drawn = {}

        @staticmethod
        def AddToBuilder(
            builder: DiagramBuilder,
            contact_results_port: OutputPort,
            meshcat: Meshcat,
            params: ContactVisualizerParams | None = None,
        ):
            """Add a visualizer to ``builder``, connect ``contact_results_port`` (a
            ComplementarityPlant's ``get_contact_results_output_port()``) to it and return
            it (``ContactVisualizer.AddToBuilder``'s call, without a QueryObject port)."""
            system = builder.AddSystem(ContactForceVisualizer_[float](meshcat, params))
            builder.Connect(contact_results_port, system.contact_results_port)
            return system

        def _Delete(self, context) -> EventStatus:
            self.Delete()
            return EventStatus.Succeeded()

        def _Publish(self, context) -> EventStatus:
            results = self.contact_results_port.Eval(context)
            self.Draw(results)
            return EventStatus.Succeeded()

        def Draw(self, results: PointContactResults) -> None:
            """Draw ``results`` now (what a publish does)."""
            p = self.params
            plant = results.plant()
            root = f"{p.prefix}/point"
            shown: dict[str, tuple[np.ndarray, np.ndarray]] = {}
            for i in range(results.num_point_pair_contacts()):
                info = results.point_pair_contact_info(i)
                f, p_WC = np.asarray(info.contact_force()), np.asarray(info.contact_point())
                norm = float(np.linalg.norm(f))
                if not norm >= p.force_threshold:
                    continue
                names = (
                    (plant.get_body(info.bodyA_index()).name(),
                     plant.get_body(info.bodyB_index()).name())
                    if plant is not None
                    else (int(info.bodyA_index()), int(info.bodyB_index()))
                )  # fmt: skip
                path = f"{root}/{names[0]}+{names[1]}/{results.candidate(i)}"
                if path not in self._visible:
                    self._add_arrow(path)
                height = norm / p.newtons_per_meter
                head = 2.0 * p.radius
                self.meshcat.SetTransform(
                    path, RigidTransform(RotationMatrix.MakeFromOneVector(f, 2), p_WC)
                )
                self.meshcat.SetTransform(f"{path}/cylinder", np.diag([1.0, 1.0, height, 1.0]))
                self.meshcat.SetTransform(f"{path}/head", RigidTransform([0, 0, -height - head]))
                self.meshcat.SetTransform(
                    f"{path}/tail",
                    RigidTransform(RotationMatrix.MakeXRotation(np.pi), [0, 0, height + head]),
                )
                shown[path] = (p_WC, f)
            for path, visible in self._visible.items():
                if visible != (path in shown):
                    self.meshcat.SetProperty(path, "visible", path in shown)
                    self._visible[path] = path in shown
            self.drawn = shown

        def _add_arrow(self, path: str) -> None:
            """The arrow's objects (a unit cylinder of length 2, scaled per publish, and two
            cones), hidden until placed."""
            p = self.params
            self.meshcat.SetProperty(path, "visible", False)
            self._visible[path] = False
            self.meshcat.SetObject(f"{path}/cylinder", Cylinder(p.radius, 2.0), p.color)
            cone = MeshcatCone(2.0 * p.radius, 2.0 * p.radius, 2.0 * p.radius)
            self.meshcat.SetObject(f"{path}/head", cone, p.color)
            self.meshcat.SetObject(f"{path}/tail", cone, p.color)

    return Impl


ContactForceVisualizer = ContactForceVisualizer_[None]
