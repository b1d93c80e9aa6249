"""The robot in motion (beyond the paper's kinetostatics): mass, damping, modes, time integration.

* :class:`Inertia`: the mass matrix in material coordinates (consistent ANCF
  mass, plates as thin discs, connectors and payload as points), the
  Kelvin-Voigt and air damping, the static <-> material coordinate map;
* :func:`natural_modes`: natural frequencies, damping ratios and mode shapes
  of any equilibrium (:class:`ModalAnalysis`, :class:`Mode`);
* :class:`GeneralizedAlpha`: the index-3 time integrator (Arnold & Bruels),
  pressures, payload and tip force functions of time; a run through many
  instants in one compiled call (:meth:`GeneralizedAlpha.advance_through`,
  :class:`Passage`);
* :func:`sample_motion`: a run sampled at fixed instants (:class:`SampledMotion`),
  :func:`piecewise_linear` pressures from a table;

docs/dynamics.md states the model and its sources.
"""

from ._inertia import Inertia
from ._integrator import (MAX_DEFAULT_STEP_S, MIN_STEPS_PER_PERIOD, STEPS_PER_PERIOD,
                          DynamicsError, DynamicState, GeneralizedAlpha, Passage, PressureRamp,
                          StepReport, default_step, warm_up_dynamics)
from ._modes import (ModalAnalysis, ModalError, Mode, ReducedSystem, natural_modes,
                     reduced_system)
from ._sampling import SampledMotion, piecewise_linear, sample_motion, sampling_step

__all__ = ["DynamicState", "DynamicsError", "GeneralizedAlpha", "Inertia",
           "MAX_DEFAULT_STEP_S", "MIN_STEPS_PER_PERIOD", "ModalAnalysis", "ModalError", "Mode",
           "Passage", "PressureRamp", "ReducedSystem", "STEPS_PER_PERIOD", "SampledMotion",
           "StepReport", "default_step", "natural_modes", "piecewise_linear", "reduced_system",
           "sample_motion", "sampling_step", "warm_up_dynamics"]
