"""How a Newton solve ends: :class:`Status`, a str-Enum whose values are the words reports,
CSV columns and JSON sidecars show."""

from __future__ import annotations

from enum import Enum


class Status(str, Enum):
    """The outcome of a solve; ``Status.converged == "converged"`` (the value is the word)."""

    converged = "converged"
    max_iterations = "max_iterations"
    step_too_small = "step_too_small"
    left_domain = "left_domain"
    singular = "singular"
    not_finite = "not_finite"
    no_equilibrium = "no_equilibrium"
    failed = "failed"

    def __str__(self) -> str:
        return self.value

    __format__ = str.__format__


#: How a solve can end: NewtonReport.status is one of these words (``reason`` says more).
STATUSES = {
    Status.converged.value: "max |R| on the free degrees of freedom is below the tolerance",
    Status.max_iterations.value: "the iteration limit was reached before convergence",
    Status.step_too_small.value: "no step along the Newton direction reduces the residual (line search failed)",
    Status.left_domain.value: "every trial step, however short, left the model's domain (material lock, "
                              "non-positive radius, collapsed edge)",
    Status.singular.value: "the tangent stiffness is singular",
    Status.not_finite.value: "the residual is NaN or inf",
    Status.no_equilibrium.value: "loading from rest cannot reach the load: a limit point or the end of the "
                                 "material's domain lies before it",
    Status.failed.value: "any other failure (see reason)",
}
