"""A compact CMA-ES (Hansen's (mu/mu_w, lambda) algorithm, default parameters), in NumPy.

Follows N. Hansen, "The CMA Evolution Strategy: A Tutorial" (arXiv:1604.00772), Table 1 and
Fig. 6: weighted recombination of the best ``mu = lambda // 2`` of ``lambda = 4 + floor(3 ln n)``
samples, cumulative step-size adaptation (CSA), and the rank-one (evolution path) plus rank-mu
covariance updates with the ``h_sigma`` stall correction. Positive recombination weights only
(the tutorial's classic setting). Ask/tell interface; the objective is evaluated by the caller
(so a whole generation can be one vmapped, jitted batch).

No dependency beyond NumPy (no CMA-ES library is installed in this environment).
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["CMAES", "cmaes_minimize"]


@dataclasses.dataclass
class CMAES:
    """CMA-ES state; create with :meth:`create`, then alternate :meth:`ask` and :meth:`tell`.

    Attributes:
        mean: (n,) distribution mean; sigma: () step size; C: (n, n) covariance;
        p_sigma, p_c: (n,) evolution paths; generation: () count; rng: NumPy generator.
        best_x: (n,) best point evaluated so far; best_f: its value.
    """

    mean: np.ndarray
    sigma: float
    C: np.ndarray
    p_sigma: np.ndarray
    p_c: np.ndarray
    lam: int
    mu: int
    weights: np.ndarray
    mu_eff: float
    c_sigma: float
    d_sigma: float
    c_c: float
    c_1: float
    c_mu: float
    chi_n: float
    rng: np.random.Generator
    generation: int = 0
    evaluations: int = 0
    best_x: np.ndarray | None = None
    best_f: float = np.inf
    _B: np.ndarray | None = None
    _D: np.ndarray | None = None
    _z: np.ndarray | None = None
    _x: np.ndarray | None = None

    @classmethod
    def create(cls, x0, sigma0: float, popsize: int | None = None, seed: int = 0) -> CMAES:
        """Start at ``x0`` (n,) with step size ``sigma0`` > 0 and Hansen's default parameters."""
        x0 = np.asarray(x0, dtype=float).ravel()
        n = x0.size
        if n < 1 or not np.all(np.isfinite(x0)):
            raise ValueError("x0: expected a non-empty finite vector")
        if not (np.isfinite(sigma0) and sigma0 > 0):
            raise ValueError(f"sigma0: expected a finite value > 0, got {sigma0!r}")
        lam = int(popsize) if popsize is not None else 4 + int(3 * np.log(n))
        if lam < 2:
            raise ValueError(f"popsize: expected >= 2, got {lam}")
        mu = lam // 2
        w = np.log((lam + 1) / 2) - np.log(np.arange(1, mu + 1))
        w = w / w.sum()
        mu_eff = 1.0 / np.sum(w**2)
        c_sigma = (mu_eff + 2) / (n + mu_eff + 5)
        d_sigma = 1 + 2 * max(0.0, np.sqrt((mu_eff - 1) / (n + 1)) - 1) + c_sigma
        c_c = (4 + mu_eff / n) / (n + 4 + 2 * mu_eff / n)
        c_1 = 2 / ((n + 1.3) ** 2 + mu_eff)
        c_mu = min(1 - c_1, 2 * (mu_eff - 2 + 1 / mu_eff) / ((n + 2) ** 2 + mu_eff))
        chi_n = np.sqrt(n) * (1 - 1 / (4 * n) + 1 / (21 * n**2))
        return cls(
            mean=x0.copy(),
            sigma=float(sigma0),
            C=np.eye(n),
            p_sigma=np.zeros(n),
            p_c=np.zeros(n),
            lam=lam,
            mu=mu,
            weights=w,
            mu_eff=float(mu_eff),
            c_sigma=float(c_sigma),
            d_sigma=float(d_sigma),
            c_c=float(c_c),
            c_1=float(c_1),
            c_mu=float(c_mu),
            chi_n=float(chi_n),
            rng=np.random.default_rng(seed),
        )

    @property
    def n(self) -> int:
        return self.mean.size

    def ask(self) -> np.ndarray:
        """(lambda, n) candidates ``x_k = m + sigma B D z_k``, ``z_k ~ N(0, I)``."""
        C = (self.C + self.C.T) / 2
        eigval, B = np.linalg.eigh(C)
        D = np.sqrt(np.maximum(eigval, 1e-20))
        z = self.rng.standard_normal((self.lam, self.n))
        y = (z * D) @ B.T
        self._B, self._D, self._z = B, D, z
        self._x = self.mean + self.sigma * y
        return self._x.copy()

    def tell(self, f) -> None:
        """Update from the values ``f`` (lambda,) of the last :meth:`ask` (NaN/inf rank last)."""
        if self._x is None:
            raise RuntimeError("tell() before ask()")
        f = np.asarray(f, dtype=float)
        if f.shape != (self.lam,):
            raise ValueError(f"f: expected shape ({self.lam},), got {f.shape}")
        f = np.where(np.isfinite(f), f, np.inf)
        self.evaluations += self.lam
        order = np.argsort(f, kind="stable")
        if f[order[0]] < self.best_f:
            self.best_f, self.best_x = float(f[order[0]]), self._x[order[0]].copy()
        n, B, D = self.n, self._B, self._D
        y = (self._x - self.mean) / self.sigma
        y_sel = y[order[: self.mu]]
        y_w = self.weights @ y_sel
        self.mean = self.mean + self.sigma * y_w
        # C^{-1/2} y_w = B D^{-1} B^T y_w
        c_inv_half_yw = B @ ((B.T @ y_w) / D)
        cs, cc = self.c_sigma, self.c_c
        self.p_sigma = (1 - cs) * self.p_sigma + np.sqrt(cs * (2 - cs) * self.mu_eff) * (
            c_inv_half_yw
        )
        self.generation += 1
        norm_ps = np.linalg.norm(self.p_sigma)
        ps_unbiased = norm_ps / np.sqrt(1 - (1 - cs) ** (2 * self.generation))
        h_sigma = float(ps_unbiased < (1.4 + 2 / (n + 1)) * self.chi_n)
        self.p_c = (1 - cc) * self.p_c + h_sigma * np.sqrt(cc * (2 - cc) * self.mu_eff) * y_w
        delta_h = (1 - h_sigma) * cc * (2 - cc)
        rank_one = np.outer(self.p_c, self.p_c)
        rank_mu = (y_sel.T * self.weights) @ y_sel
        self.C = (
            (1 + self.c_1 * delta_h - self.c_1 - self.c_mu) * self.C
            + self.c_1 * rank_one
            + self.c_mu * rank_mu
        )
        self.sigma *= float(np.exp((cs / self.d_sigma) * (norm_ps / self.chi_n - 1)))
        self._x = None


def cmaes_minimize(f, x0, sigma0: float, max_evals: int, popsize=None, seed=0, tol_f=0.0):
    """Minimise ``f(X (lambda, n)) -> (lambda,)`` with :class:`CMAES` (batch objective).

    Stops after ``max_evals`` evaluations or when the best value is <= ``tol_f``; returns the
    final :class:`CMAES` (``best_x``, ``best_f``, ``evaluations``).
    """
    es = CMAES.create(x0, sigma0, popsize, seed)
    while es.evaluations + es.lam <= max_evals and es.best_f > tol_f:
        X = es.ask()
        es.tell(f(X))
    return es
