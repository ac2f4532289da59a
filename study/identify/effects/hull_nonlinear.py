"""Higher-order hull terms the model lacks or has wrong: they become free coefficients.

What is freed: the terms the model omits (``omit`` in its config), else the kind's nonlinear hull
terms (``options.terms`` in ``conf/effect/hull_nonlinear.yaml``, per kind and equation) that the
model does not already identify. Their columns come from the kind's own compiled equations (linear
in each coefficient). Sources of the term lists: Yasukawa & Yoshimura (2015) eqs. 9-11 (mmg); Song
et al. (2025) eq. 2 (waterjet); Fossen's mariner.m (abkowitz); Du et al. (2016) eq. 3 (auv).
"""
from __future__ import annotations

from .base import Effect


class HullNonlinear(Effect):
    physics = "higher-order hull terms the model lacks or has wrong"
    enters = "extra free coefficients in the regression (the kind's own equations)"
    source = "Yasukawa & Yoshimura (2015) eqs. 9-11; Abkowitz (1964); Song et al. 2025 eq. 2; Du et al. 2016 eq. 3"

    def __init__(self, name, params=None, terms=None):
        super().__init__(name, params)
        self.terms = {k: {eq: list(v or []) for eq, v in (eqs or {}).items()} for k, eqs in (terms or {}).items()}

    def applies(self, problem):
        if problem.base.kind_name not in self.terms and not problem.omit:
            return f"no nonlinear hull terms listed for vessel kind '{problem.base.kind_name}'"
        if not self.free_coefficients(problem):
            return "the model already identifies every nonlinear hull term"
        return None

    def free_coefficients(self, problem):
        if problem.omit:
            return {c: problem.equation_of(c) for c in problem.omit}
        free = set(problem.model_free)
        return {c: eq for eq, cs in self.terms.get(problem.base.kind_name, {}).items() for c in cs if c not in free}
