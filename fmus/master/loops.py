"""Algebraic loops: cycles of direct feedthrough through the connections, found before a run and solved
at every communication point (:class:`LoopSolver`).

A loop exists when an output depends, through the FMUs' declared output dependencies (modelDescription
``ModelStructure``; an output that declares none depends on every input, as the standard says) and the
connections, on itself: ``a.y -> b.u -> b.y -> a.u -> a.y``.  Stepping such blocks one after another
would leave the loop inconsistent, and iterating them (what a Jacobi round did) climbs without bound
when the loop has no solution (``y = u + 1`` fed back: 2, 3, 5, ...).

After every round (and at the initial point) the solver makes the loop consistent: with ``v`` the loop's
outputs, it solves ``g(v) = v`` by Newton's method, where ``g`` sets the loop members' inputs from ``v``
(at the end of the step: the FMUs' states are not touched) and reads their outputs back.  The Jacobian
``dg/dv - I`` is built by finite differences (one evaluation per loop output; a linear loop converges in
one Newton step) and reused while it converges.  A loop whose Jacobian is singular has no unique
solution, one that does not converge has none the solver can vouch for: both are a
:class:`~fmus.master.errors.SimulationError` naming the loop's path and what to do.  The largest residual
and the iterations are reported (:meth:`LoopSolver.report`).
"""

from __future__ import annotations

import numpy as np

from .errors import SimulationError, check
from .instance import Instance

__all__ = ["AlgebraicLoop", "find_loops", "LoopSolver"]

#: residual accepted: |g(v) - v| <= TOLERANCE * (1 + |v|) (infinity norms)
TOLERANCE = 1e-12
MAX_ITERATIONS = 25
_ADVICE = ("break the loop with a block that has no direct feedthrough (a delay, a first-order filter, "
           "a plant whose output is C x) or remove the feedthrough (D = 0)")


class AlgebraicLoop:
    """One strongly connected set of outputs (indices into the shared output vector), its members
    (the instances owning them, in stepping order) and a readable path through it."""

    def __init__(self, outputs: list[int], members: list[Instance], path: str):
        self.outputs = np.array(sorted(outputs), dtype=int)
        self.members, self.path = members, path


def find_loops(order: list[Instance]) -> list[AlgebraicLoop]:
    """The algebraic loops of wired instances (:func:`fmus.master.wiring.wire` ran), upstream first."""
    names, owner = [], []                  # per output of the shared vector: its name, its instance
    for inst in order:
        for output in inst.outputs:
            names.append(f"{inst.name}.{output}")
            owner.append(inst)
    offsets = np.cumsum([0] + [len(inst.outputs) for inst in order])
    successors: list[list[tuple[int, str]]] = [[] for _ in names]
    for inst, offset in zip(order, offsets):
        if not inst.input_vrs:
            continue
        by_vr = {inst.variables[name].valueReference: name for name in inst.variables
                 if inst.variables[name].causality == "input"}
        fed = dict(zip((by_vr[vr] for vr in inst.input_vrs), inst.input_sources))
        for k, depends_on in enumerate(inst.output_dependencies()):
            for input_name in (fed if depends_on is None else depends_on):
                if input_name in fed:
                    successors[fed[input_name]].append((offset + k, f"{inst.name}.{input_name}"))
    edges = [[target for target, _ in row] for row in successors]
    loops = []
    for component in reversed(_strongly_connected(edges)):       # Tarjan finds them downstream first
        if len(component) == 1 and component[0] not in edges[component[0]]:
            continue
        members = [inst for inst in order if any(owner[i] is inst for i in component)]
        loops.append(AlgebraicLoop(component, members, _path(component, successors, names)))
    return loops


def _strongly_connected(edges: list[list[int]]) -> list[list[int]]:
    """Tarjan's strongly connected components (iterative), in reverse topological order."""
    index, low, on_stack, stack, found, counter = {}, {}, set(), [], [], 0
    for root in range(len(edges)):
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            node, position = work.pop()
            if position == 0:
                index[node] = low[node] = counter
                counter += 1
                stack.append(node)
                on_stack.add(node)
            for k in range(position, len(edges[node])):
                child = edges[node][k]
                if child not in index:
                    work += [(node, k + 1), (child, 0)]
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    found.append(component)
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
    return found


def _path(component: list[int], successors, names: list[str]) -> str:
    """``a.y -> b.u -> b.y -> a.u -> a.y``: a shortest cycle through the component's first output."""
    inside, start = set(component), min(component)
    previous = {start: None}
    frontier = [start]
    while frontier:                                        # breadth first, back to start
        following = []
        for node in frontier:
            for target, via in successors[node]:
                if target not in inside:
                    continue
                if target == start:
                    steps = [(node, via)]
                    while previous[steps[-1][0]] is not None:
                        steps.append(previous[steps[-1][0]])
                    hops = []
                    for source, into in reversed(steps):
                        hops += [names[source], into]
                    return " -> ".join(hops + [names[start]])
                if target not in previous:
                    previous[target] = (node, via)
                    following.append(target)
        frontier = following
    return " -> ".join(names[i] for i in component)


class LoopSolver:
    """Makes every algebraic loop of a stepper consistent at a communication point (module docstring)."""

    def __init__(self, loops: list[AlgebraicLoop], live: np.ndarray, logger):
        self.loops, self.live, self.logger = loops, live, logger
        self._jacobians: list[np.ndarray | None] = [None] * len(loops)
        self.points = 0
        self.largest_residual = 0.0
        self.most_iterations = 0

    def solve(self, t: float) -> None:
        for k, loop in enumerate(self.loops):
            self._solve(k, loop, t)
        self.points += 1

    def _solve(self, k: int, loop: AlgebraicLoop, t: float) -> None:
        v = self.live[loop.outputs].copy()
        residual = self._evaluate(loop, v) - v
        for iteration in range(MAX_ITERATIONS + 1):
            size = np.max(np.abs(residual)) if residual.size else 0.0
            if not np.isfinite(size):
                break
            if size <= TOLERANCE * (1.0 + np.max(np.abs(v))):
                self.most_iterations = max(self.most_iterations, iteration)
                self.largest_residual = max(self.largest_residual, float(size))
                return
            jacobian = self._jacobians[k]
            if jacobian is None or iteration > 0:          # reused only for the first step of a point
                jacobian = self._jacobians[k] = self._jacobian(loop, v, residual, t)
            step = np.linalg.solve(jacobian, -residual)
            v = v + step
            residual = self._evaluate(loop, v) - v
        raise SimulationError(f"algebraic loop {loop.path}: Newton's method did not converge at t = {t:.9g} "
                              f"(residual {np.max(np.abs(residual)):.3g} after {MAX_ITERATIONS} iterations): "
                              f"the loop may have no solution; {_ADVICE}")

    def _jacobian(self, loop: AlgebraicLoop, v: np.ndarray, residual: np.ndarray, t: float) -> np.ndarray:
        """``d(g(v) - v)/dv`` by forward differences; a :class:`SimulationError` if it is singular."""
        jacobian = np.empty((v.size, v.size))
        for j in range(v.size):
            delta = 1e-7 * max(1.0, abs(v[j]))
            moved = v.copy()
            moved[j] += delta
            jacobian[:, j] = ((self._evaluate(loop, moved) - moved) - residual) / delta
        if not np.all(np.isfinite(jacobian)) or np.linalg.cond(jacobian) > 1e12:
            raise SimulationError(
                f"algebraic loop {loop.path} has no unique solution at t = {t:.9g} (the loop gain is 1: "
                f"d(g(v) - v)/dv is singular, e.g. y = u + 1 fed back to u); {_ADVICE}")
        return jacobian

    def _evaluate(self, loop: AlgebraicLoop, v: np.ndarray) -> np.ndarray:
        """``g(v)``: the loop's outputs when its members' inputs are taken from ``v``."""
        live = self.live
        live[loop.outputs] = v
        source = live.copy()
        for inst in loop.members:
            inst.input_values[:] = source[inst.input_sources]
            check(inst, self.logger, "setting inputs (algebraic loop)", inst.set_inputs())
        for inst in loop.members:
            check(inst, self.logger, "reading outputs (algebraic loop)", inst.refresh_outputs())
        return live[loop.outputs].copy()

    def report(self) -> str:
        paths = "; ".join(loop.path for loop in self.loops)
        return (f"algebraic loop{'s' if len(self.loops) > 1 else ''} {paths} solved at {self.points} "
                f"communication points by Newton's method: at most {self.most_iterations} iterations, "
                f"largest residual {self.largest_residual:.2g} (tolerance {TOLERANCE:g} relative)")
