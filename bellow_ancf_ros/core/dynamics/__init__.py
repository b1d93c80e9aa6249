"""The robot in motion (beyond the paper's kinetostatics): mass, damping, modes, time integration.

* :class:`Inertia`: the mass matrix in material coordinates (consistent ANCF
  mass, plates as thin discs, connectors and payload as points), the
  Kelvin-Voigt and air damping, the static <-> material coordinate map;
* :func:`natural_modes`: natural frequencies, damping ratios and mode shapes
  of any equilibrium (:class:`ModalAnalysis`, :class:`Mode`);

docs/dynamics.md states the model and its sources.
"""

from ._inertia import Inertia
from ._modes import ModalAnalysis, ModalError, Mode, natural_modes

__all__ = ["Inertia", "ModalAnalysis", "ModalError", "Mode", "natural_modes"]
