"""Systems and settings the tests share, each built once here."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import absorber_jax as aj

# tolerances well below what the tests compare: shooting residual and integration
TIGHT = dict(method=aj.Shooting(tol=1e-10, newton_steps=40),
             integrator=aj.Integrator(rtol=1e-12, atol=1e-12))

# a 3-storey shear building (ground floor first) with Den Hartog tuned mass dampers
MASSES = [2.0e3, 2.0e3, 1.5e3]                 # kg, ground floor first
STOREYS = [4.0e6, 3.5e6, 3.0e6]               # N/m
RAYLEIGH = (0.2, 5e-4)


def _den_hartog_dampers():
    """Three dampers, one per mode, each at the floor where its mode moves most, tuned by
    Den Hartog on the mode's effective mass there (1 / φ², mass-normalised modes); mass
    ratios 5 %, 2 %, 1 %.  (numpy, independently of the library.)"""
    m, k = np.array(MASSES), np.array(STOREYS)
    K = np.array([[k[0] + k[1], -k[1], 0.0], [-k[1], k[1] + k[2], -k[2]], [0.0, -k[2], k[2]]])
    lam, V = np.linalg.eigh(np.diag(m**-0.5) @ K @ np.diag(m**-0.5))
    phi = np.diag(m**-0.5) @ V
    out = []
    for r, mu in enumerate((0.05, 0.02, 0.01)):
        j = int(np.argmax(np.abs(phi[:, r])))
        mt = mu / phi[j, r] ** 2
        wt = np.sqrt(lam[r]) / (1 + mu)
        zt = np.sqrt(3 * mu / (8 * (1 + mu) ** 3))
        out.append((f"floor{j + 1}", mt, mt * wt**2, 2 * zt * mt * wt))
    return out


TMDS = _den_hartog_dampers()


# NLvib example 03: two masses, a unilateral spring on x1 beyond 1
K03 = np.array([[1.0, -1.0], [-1.0, 2.0]])


def nlvib03():
    st = aj.structure_from_matrices(np.eye(2), K03, damping=0.03 * K03)
    spring = aj.Contact("x1", gap=1.0, contact=aj.KelvinVoigt(stiffness=100.0, damping=0.0,
                                                              adhesive=True))
    return aj.StructuralSystem(st, [spring], load="x2", observe="x2")


# a hardening oscillator: one mass with a one-sided spring (reference_jumps' scene)
HARD = dict(c=0.02, F0=0.05, k_c=3.0, g=0.5)   # reference_jumps' scene (m = k = 1)


def hardening():
    """One DOF, m = k = 1, c = 0.02, a one-sided spring k_c = 3 beyond q = 0.5."""
    st = aj.structure_from_matrices(np.eye(1), np.eye(1), damping=HARD["c"] * np.eye(1))
    stop = aj.Contact("x1", gap=HARD["g"], contact=aj.KelvinVoigt(stiffness=HARD["k_c"],
                                                                  damping=0.0,
                                                                  adhesive=True))
    return aj.StructuralSystem(st, [stop], load="x1")


# a linear tuned mass damper on an undamped primary
M, K, WN = 1.0, 1e4, 100.0


def tmd(mu, f, zeta):
    """A linear tuned mass damper on an undamped primary: the impact absorber with no gap and
    a Kelvin–Voigt contact is a spring and dashpot in both directions."""
    m = mu * M
    ka = m * (f * WN) ** 2
    law = aj.KelvinVoigt(stiffness=ka, damping=2 * zeta * np.sqrt(ka * m), adhesive=True)
    return aj.ImpactAbsorber(M=M, k=K, c=0.0, m=m, gap=0.0, contact=law)


class CubicSpring(aj.AbstractSpring):
    """``f = k3 (x_dof - x_other)³`` between two degrees of freedom, or to ground: an element
    written as a user would, from the public API alone."""

    dof: str = eqx.field(static=True)
    k3: float
    other: str | None = eqx.field(static=True, default=None)
    name: str | None = eqx.field(static=True, default=None)
    kind = "cubic"

    def evaluate(self, x, v, z):
        f = self.k3 * (x[0] - x[1]) ** 3
        return jnp.stack([-f, f]), None

    def energy(self, x, v, z):
        return 0.25 * self.k3 * (x[0] - x[1]) ** 4
