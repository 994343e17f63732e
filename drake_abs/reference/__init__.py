"""Reference simulators as steppers: Drake's own discrete MultibodyPlant (SAP, Similar, Lagged)
on a scene's model files, and MuJoCo (a model file or a gymnasium environment), each returning
the one step record (:class:`drake_abs.contact.step.Step`) so that they run in the same engine
(:func:`drake_abs.engine.open_loop`, :func:`~drake_abs.engine.rollout`,
:func:`~drake_abs.engine.record`) as this package's own steppers.

- :class:`~drake_abs.reference.drake_plant.DrakePlantStepper`: a scene's Drake twin
  (:func:`~drake_abs.reference.drake_twin.make_drake_twin`), Jacobians by AutoDiffXd.
- :class:`~drake_abs.reference.mujoco_plant.MujocoStepper`: MuJoCo's ``mj_step``, ``frame_skip``
  times per step, Jacobians by MuJoCo's finite differences (``mjd_transitionFD``). MuJoCo is an
  optional dependency, imported only when a MuJoCo stepper is made.
- :mod:`~drake_abs.reference.scene_sources`: our scenes' twins in both (Drake's SAP twin, and
  gymnasium's Hopper / HalfCheetah or an MJCF box in MuJoCo) as steppers in the scenes' own
  coordinates and units, checked name by name, with contact probes: sources of transition data.

Import the modules themselves (``from drake_abs.reference.drake_plant import
DrakePlantStepper``): this package imports neither Drake nor MuJoCo by itself.
"""

__all__: list[str] = []
