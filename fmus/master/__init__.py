"""The co-simulation master: a :class:`System` of FMU instances run by a :class:`Session` (:func:`cosimulate`).

By concern:

* :mod:`.system` -- what is simulated (:class:`Component`, :class:`Connection`, :class:`System`);
* :mod:`.cache` -- the FMUs extracted once per content; :mod:`.log` -- their log messages;
* :mod:`.instance` -- what the master needs of an instance, with the FMI 2.0 and FMI 3.0
  implementations :mod:`.fmi2` and :mod:`.fmi3` (the version chosen where the FMU is opened:
  :func:`~.session.open_instance`);
* :mod:`.wiring` -- connections -> each instance's inputs in the shared output vector;
* :mod:`.round` -- one co-simulation round (Python, or in one call of an obsfmu binary);
* :mod:`.loop` -- the fixed-step loop; :mod:`.adaptive` -- the step-size controller around the error
  estimate of :mod:`.error_estimate` (step doubling);
* :mod:`.session` -- :class:`Session`, :func:`cosimulate`; :mod:`.recorder` -- where the points go.
"""

from .errors import SimulationError
from .loop import communication_points
from .recorder import MemoryRecorder, Recorder
from .session import COUPLINGS, ORDERS, Session, cosimulate
from .system import Component, Connection, System

__all__ = ["Component", "Connection", "System", "SimulationError", "Session", "Recorder", "MemoryRecorder",
           "cosimulate", "communication_points", "ORDERS", "COUPLINGS"]
