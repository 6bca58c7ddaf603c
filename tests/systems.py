"""Textbook test systems with known answers, defined once for every test module.

* :func:`bautin_system` - the Hopf/Bautin normal form embedded in a stable 6-D system,
  deformed by an invertible nonlinear change of coordinates and rotated.
* :data:`HOPF_NF`, :data:`FOLD_NF` - planar radial normal forms r' = r g(mu, r^2),
  theta' = omega, plus a stable linear 3-block, rotated (Hopf; fold of cycles at mu = -1).
* :func:`pd_system` - a planar Hopf cycle with a transverse "Moebius" block whose
  Floquet multipliers are known in closed form: a period doubling at nu = (ALPHA/BETA)^2.
* :func:`pd_system_2p` - the same with ALPHA a parameter: the PD curve nu = ALPHA^2.
* :func:`bautin_flip_system` - the same fold of cycles with a transverse block whose
  multiplier passes -1 on it: a fold-flip point (LPPD) in closed form.
* :func:`ns_system` - a Hopf cycle with a transverse oscillator: the Neimark-Sacker curve
  gamma = beta^2 with its multipliers' angle pi / (1 + beta) in closed form.
* :data:`BAUTIN_NF` - the radial Bautin normal form r' = r (mu + l1 r^2 - r^4): its fold of
  cycles is the curve l1^2 + 4 mu = 0, l1 > 0.
* :func:`planar_system` - a planar system (PD and NS impossible).
* :func:`saddle_node`, :func:`pitchfork`, :func:`s_shaped_hopf` - equilibria with a fold,
  a symmetric pitchfork, and an S-shaped curve with a Hopf point on each outer branch.
* :func:`two_hopf_system` - one family of cycles joining two Hopf points (closed form);
  :func:`bogdanov_takens_system` - cycles ending at a homoclinic orbit (shooting
  reference); :func:`pitchfork_cycles_system` - two branch points of cycles near a fold.
* :func:`lorenz` - the Lorenz system (sigma = 10, beta = 8/3), Hopf of C+ at
  rho = sigma (sigma + beta + 3) / (sigma - beta - 1), subcritical.
* :func:`clamped_oscillator` / :func:`clamped_oscillator_limited` - a damped oscillator
  pulled back by a "current" that may not reverse (held at zero while it would): the same
  system as a piecewise-smooth flow and as the simulator's limited vector field, with an
  upper limit the first overshoot grazes; with the coupling a = 0 the first overshoot is
  d exp(-zeta pi / sqrt(1 - zeta^2)) in closed form.
* :func:`saturated_oscillator` - a planar oscillator with saturated negative damping,
  y' = -x - 2 zeta y + k sat(y): a stable limit cycle made of linear and saturated pieces.
* :func:`linear_dde`, :func:`hutchinson`, :func:`mackey_glass` - delay equations: x' =
  -a x(t - tau) (roots W_k(-a tau) / tau, Hopf at tau = pi / (2 a)), the delayed logistic
  equation (Hopf at r tau = pi / 2, supercritical) and the Mackey-Glass equation (a period
  doubling of its cycles).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.dynamics.delay import DelayDifferentialSystem
from maglev_match.dynamics.system import System


def _orthogonal(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.standard_normal((n, n)))
    return q * np.sign(np.diag(r))


# ----------------------------------------------------------------------- Bautin normal form
OMEGA = 1.7
GAMMA = 0.8  # Im of the cubic coefficient (frequency shift), must not change l1 or l2
DELTA = -0.3  # Im of the quintic coefficient
DIM = 6


def bautin_system(deform: bool = True, seed: int = 3) -> System:
    """z' = (beta1 + i OMEGA) z + (beta2 + i GAMMA) z|z|^2 + (s + i DELTA) z|z|^4 in
    (y1, y2) = (Re z, Im z), four stable coordinates driven by the centre coordinates,
    then deformed by an explicit, invertible change of coordinates w = phi(y) with
    quadratic and cubic terms, and rotated: x = R w. Parameters (beta1, beta2, s).

    With <q, q> = 1 the expected coefficients are l1 = 2 beta2 / OMEGA and, at beta2 = 0,
    l2 = 4 s / OMEGA (the centre coordinate is z = sqrt(2) w in the normal-form variable w).
    """
    R = jnp.asarray(_orthogonal(DIM, seed))
    A_s = jnp.array([[-1.0, 2.0, 0.0, 0.0], [-2.0, -1.0, 0.5, 0.0],
                     [0.0, 0.0, -3.0, 1.0], [0.0, 0.0, 0.0, -0.5]])
    k = 0.4 if deform else 0.0

    def g(y, p):
        b1, b2, s = p[0], p[1], p[2]
        y1, y2 = y[0], y[1]
        r2 = y1**2 + y2**2
        re = b1 * y1 - OMEGA * y2 + (b2 * y1 - GAMMA * y2) * r2 + (s * y1 - DELTA * y2) * r2**2
        im = b1 * y2 + OMEGA * y1 + (b2 * y2 + GAMMA * y1) * r2 + (s * y2 + DELTA * y1) * r2**2
        ys = y[2:]
        drive = jnp.array([y1**2, y1 * y2, y2**3, y1 * y2**2])
        return jnp.concatenate([jnp.stack([re, im]), A_s @ ys + drive])

    def hs(y0, y1):
        return jnp.stack([y0 * y1, y1**2 - y0**3, y0**2 * y1, y0 * y1**2])

    def phi(y):  # w1 depends on y0 only and w_s on (y0, y1) only: explicitly invertible
        w1 = y[1] + k * (y[0] ** 2 - 0.5 * y[0] ** 3)
        return jnp.concatenate([y[:1], jnp.stack([w1]), y[2:] + k * hs(y[0], y[1])])

    def phi_inv(w):
        y1 = w[1] - k * (w[0] ** 2 - 0.5 * w[0] ** 3)
        return jnp.concatenate([w[:1], jnp.stack([y1]), w[2:] - k * hs(w[0], y1)])

    def rhs(x, p):
        y = phi_inv(R.T @ x)
        return R @ jax.jvp(phi, (y,), (g(y, p),))[1]

    return System(rhs=rhs, p=np.array([0.0, 0.0, 0.45]), param_names=("beta1", "beta2", "s"),
                  state_names=tuple(f"x{j}" for j in range(DIM)), name="bautin")


# ------------------------------------------------------------- radial normal forms of cycles
CYCLE_OMEGA = 2.0
LINEAR_PART = np.array([[-1.0, 0.0, 0.0], [0.0, -2.0, 1.0], [0.0, -1.0, -3.0]])
Q5, _ = np.linalg.qr(np.random.default_rng(7).normal(size=(5, 5)))
_QJ = jnp.asarray(Q5)


def embedded(radial) -> System:
    """Planar system r' = r g(mu, r^2), theta' = omega, plus a stable linear 3-block,
    rotated by a fixed orthogonal matrix (so no coordinate is special)."""

    def rhs(x, p):
        mu, om, l1 = p[0], p[1], p[2]
        z = _QJ.T @ x
        a, b = z[0], z[1]
        g = radial(mu, l1, a * a + b * b)
        w = jnp.asarray(LINEAR_PART) @ z[2:]
        dz = jnp.concatenate([jnp.stack([g * a - om * b, om * a + g * b]), w])
        return _QJ @ dz

    return System(
        rhs=rhs, p=np.array([0.0, CYCLE_OMEGA, -1.0]), param_names=("mu", "omega", "l1"),
        state_names=tuple(f"x{i}" for i in range(5)),
        observables={
            "radius": lambda x, p: jnp.sqrt(jnp.sum((_QJ.T @ x)[:2] ** 2)),
            "x0": lambda x, p: x[0],
        },
    )


HOPF_NF = embedded(lambda mu, l1, r2: mu + l1 * r2)
FOLD_NF = embedded(lambda mu, l1, r2: mu + 2.0 * r2 - r2 * r2)
BAUTIN_NF = embedded(lambda mu, l1, r2: mu + l1 * r2 - r2 * r2)
Q_CRIT = Q5 @ np.array([1.0, -1.0j, 0, 0, 0]) / math.sqrt(2.0)


# ------------------------------------------------------------------------ period doubling
PD_OMEGA = 2.0 * math.pi  # period 1
PD_ALPHA = 0.5
PD_BETA = 1.0
PD_NU = (PD_ALPHA / PD_BETA) ** 2  # the period doubling


def pd_system() -> System:
    """x1' = nu x1 - w x2 - x1 r^2, x2' = w x1 + nu x2 - x2 r^2 (cycle r = sqrt(nu),
    period 2 pi / w), and a transverse block y = (u, v):

        y' = (w/2) J y - ALPHA y + BETA [[x1, x2], [x2, -x1]] y,     J = [[0, -1], [1, 0]].

    On the cycle x = sqrt(nu) (cos w t, sin w t) the coefficient of BETA is
    sqrt(nu) R(w t/2) diag(1, -1) R(-w t/2), so in the frame rotating by w t / 2 the block
    is diagonal and the monodromy of y is R(pi) diag(e^{(-ALPHA +- BETA sqrt(nu)) T}):
    multipliers -exp((-ALPHA + BETA sqrt(nu)) T), -exp((-ALPHA - BETA sqrt(nu)) T), and
    exp(-2 nu T), 1 from the planar part. A period doubling (multiplier -1) at
    nu = (ALPHA / BETA)^2, exactly; the Hopf point is nu = 0."""

    def rhs(x, p):
        nu = p[0]
        x1, x2, u, v = x[0], x[1], x[2], x[3]
        r2 = x1 * x1 + x2 * x2
        w = PD_OMEGA
        du = -0.5 * w * v - PD_ALPHA * u + PD_BETA * (x1 * u + x2 * v)
        dv = 0.5 * w * u - PD_ALPHA * v + PD_BETA * (x2 * u - x1 * v)
        return jnp.stack([nu * x1 - w * x2 - x1 * r2, w * x1 + nu * x2 - x2 * r2, du, dv])

    return System(rhs=rhs, p=np.array([0.0]), param_names=("nu",),
                  state_names=("x1", "x2", "u", "v"),
                  observables={"radius": lambda x, p: jnp.sqrt(x[0] ** 2 + x[1] ** 2)},
                  name="period doubling")


def pd_system_2p() -> System:
    """:func:`pd_system` with the damping ALPHA of the transverse block a second parameter
    ``alpha``: the period doubling is the curve nu = (alpha / BETA)^2 (alpha > 0) in the
    (nu, alpha) plane, in closed form (same derivation)."""

    def rhs(x, p):
        nu, alpha = p[0], p[1]
        x1, x2, u, v = x[0], x[1], x[2], x[3]
        r2 = x1 * x1 + x2 * x2
        w = PD_OMEGA
        du = -0.5 * w * v - alpha * u + PD_BETA * (x1 * u + x2 * v)
        dv = 0.5 * w * u - alpha * v + PD_BETA * (x2 * u - x1 * v)
        return jnp.stack([nu * x1 - w * x2 - x1 * r2, w * x1 + nu * x2 - x2 * r2, du, dv])

    return System(rhs=rhs, p=np.array([0.0, PD_ALPHA]), param_names=("nu", "alpha"),
                  state_names=("x1", "x2", "u", "v"),
                  observables={"radius": lambda x, p: jnp.sqrt(x[0] ** 2 + x[1] ** 2)},
                  name="period doubling (2 parameters)")


FLIP_BETA = 1.0


def bautin_flip_system() -> System:
    """The Bautin normal form r' = r (mu + l1 r^2 - r^4), theta' = PD_OMEGA (period 1) in
    (x1, x2), with :func:`pd_system`'s transverse "Moebius" block of damping ``alpha``:

        y' = (w/2) J y - alpha y + FLIP_BETA [[x1, x2], [x2, -x1]] y.

    On a cycle of radius r the block's multipliers are -exp(-alpha +- FLIP_BETA r) (the
    derivation of :func:`pd_system`), the planar part gives 1 and exp(T dg/dr r) (1 again
    at the fold). The fold of cycles is l1^2 + 4 mu = 0 with r^2 = l1 / 2; on it a
    multiplier passes -1 where FLIP_BETA r = alpha: a fold-flip point (LPPD) at
    l1 = 2 (alpha / FLIP_BETA)^2, mu = -l1^2 / 4. Parameters (mu, l1, alpha)."""

    def rhs(x, p):
        mu, l1, alpha = p[0], p[1], p[2]
        x1, x2, u, v = x[0], x[1], x[2], x[3]
        r2 = x1 * x1 + x2 * x2
        g = mu + l1 * r2 - r2 * r2
        w = PD_OMEGA
        du = -0.5 * w * v - alpha * u + FLIP_BETA * (x1 * u + x2 * v)
        dv = 0.5 * w * u - alpha * v + FLIP_BETA * (x2 * u - x1 * v)
        return jnp.stack([g * x1 - w * x2, w * x1 + g * x2, du, dv])

    return System(rhs=rhs, p=np.array([0.0, 1.0, 0.5]), param_names=("mu", "l1", "alpha"),
                  state_names=("x1", "x2", "u", "v"),
                  observables={"radius": lambda x, p: jnp.sqrt(x[0] ** 2 + x[1] ** 2)},
                  name="Bautin with a flip block")


NS_OMEGA = 0.5  # frequency of the transverse oscillator
NS_ALPHA = 1.1  # damping of the "Moebius" block: its multiplier passes -1 at beta = alpha^2
NS_SEED = 5


def ns_system() -> System:
    """A planar Hopf cycle with an amplitude-dependent frequency and a transverse
    oscillator whose Floquet multipliers are known in closed form (a torus, i.e.
    Neimark-Sacker, curve of cycles) and :func:`pd_system`'s transverse "Moebius" block
    q = (q1, q2), rotated by a fixed orthogonal 6 x 6 matrix:

        x' = beta x - om y - x r^2,   y' = om x + beta y - y r^2,   om = 1 + r^2,
        u' = a u - OMEGA w - (u^2 + w^2) u,  w' = OMEGA u + a w - (u^2 + w^2) w,
        q' = (om / 2) J q - ALPHA q + [[x, y], [y, -x]] q,   a = gamma - r^4,
        r^2 = x^2 + y^2,   J = [[0, -1], [1, 0]].

    The cycle u = w = q = 0, r^2 = beta (beta > 0) has the period T = 2 pi / (1 + beta).
    Along it the linearisation is block diagonal (the (u, w) terms are linear in (u, w) with
    coefficients that depend on r only, and vanish at u = w = 0 with their x-derivatives),
    the (u, w) block constant: e^{T (a I + OMEGA J)}; the q block as in :func:`pd_system`
    (the cycle turns at the constant rate om = 1 + beta). Multipliers: 1, exp(-2 beta T)
    (the planar part), exp((gamma - beta^2) T) e^{+- i OMEGA T} and
    -exp((-ALPHA +- sqrt(beta)) T). A Neimark-Sacker point where the pair crosses the
    unit circle: the curve gamma = beta^2, with the multipliers' angle theta = OMEGA T =
    pi / (1 + beta) (OMEGA = 1/2), kappa = cos theta: R3 (kappa = -1/2, theta = 2 pi / 3)
    at beta = 1/2, gamma = 1/4; R4 (kappa = 0) at beta = 1, gamma = 1; theta -> pi (R2)
    only as beta -> 0; a real multiplier passes -1 on it at beta = ALPHA^2 = 1.21
    (flip-NS, PDNS: gamma = 1.4641). Parameters (beta, gamma)."""
    R = jnp.asarray(_orthogonal(6, NS_SEED))

    def rhs(x, p):
        beta, gamma = p[0], p[1]
        v = R.T @ x
        r2 = v[0] ** 2 + v[1] ** 2
        om = 1.0 + r2
        a = gamma - r2 * r2
        q2 = v[2] ** 2 + v[3] ** 2
        dv = jnp.stack([beta * v[0] - om * v[1] - v[0] * r2, om * v[0] + beta * v[1] - v[1] * r2,
                        a * v[2] - NS_OMEGA * v[3] - q2 * v[2],
                        NS_OMEGA * v[2] + a * v[3] - q2 * v[3],
                        -0.5 * om * v[5] - NS_ALPHA * v[4] + v[0] * v[4] + v[1] * v[5],
                        0.5 * om * v[4] - NS_ALPHA * v[5] + v[1] * v[4] - v[0] * v[5]])
        return R @ dv

    return System(rhs=rhs, p=np.array([0.0, 0.36]), param_names=("beta", "gamma"),
                  state_names=("x1", "x2", "x3", "x4", "x5", "x6"),
                  observables={"radius": lambda x, p: jnp.sqrt(jnp.sum((R.T @ x)[:2] ** 2))},
                  name="torus (Neimark-Sacker) curve")


def ns_plane_vector() -> np.ndarray:
    """The critical eigenvector of :func:`ns_system`'s Hopf point beta = 0 (frequency 1)."""
    return np.asarray(_orthogonal(6, NS_SEED)) @ (np.array([1.0, -1.0j, 0, 0, 0, 0])
                                                  / math.sqrt(2.0))


def pd_multipliers(nu: float) -> np.ndarray:
    """The closed-form Floquet multipliers of :func:`pd_system`'s cycle at nu > 0."""
    T = 2.0 * math.pi / PD_OMEGA
    s = math.sqrt(nu)
    return np.array([1.0, math.exp(-2 * nu * T), -math.exp((-PD_ALPHA + PD_BETA * s) * T),
                     -math.exp((-PD_ALPHA - PD_BETA * s) * T)])


def planar_system() -> System:
    """A planar Hopf normal form with a frequency that depends on the amplitude (PD and NS
    are impossible in the plane): r' = r (mu - r^2), theta' = 1 + r^2."""

    def rhs(x, p):
        mu = p[0]
        r2 = x[0] ** 2 + x[1] ** 2
        om = 1.0 + r2
        return jnp.stack([mu * x[0] - om * x[1] - x[0] * r2,
                          om * x[0] + mu * x[1] - x[1] * r2])

    return System(rhs=rhs, p=np.array([0.0]), param_names=("mu",), state_names=("x", "y"),
                  observables={"radius": lambda x, p: jnp.sqrt(x[0] ** 2 + x[1] ** 2)},
                  name="planar")


# ------------------------------------------------------------------- ends of cycle branches
TWO_HOPF_K = 0.3  # amplitude dependence of the frequency


def two_hopf_system() -> System:
    """A planar system whose one family of cycles joins two Hopf points:

        r' = r (mu (1 - mu) - r^2),   theta' = 1 + K r^2       (K = TWO_HOPF_K),

    in Cartesian coordinates (x, y) = r (cos theta, sin theta). The equilibrium 0 has the
    eigenvalues mu (1 - mu) +- i: Hopf points at mu = 0 and mu = 1 (crossing speeds +1 and
    -1, both supercritical), and for 0 < mu < 1 the cycle r^2 = mu (1 - mu), period
    2 pi / (1 + K mu (1 - mu)), multipliers 1 and exp(-2 mu (1 - mu) T), in closed form. The
    family shrinks to the equilibrium at both ends."""

    def rhs(x, p):
        mu = p[0]
        r2 = x[0] ** 2 + x[1] ** 2
        g = mu * (1.0 - mu) - r2
        om = 1.0 + TWO_HOPF_K * r2
        return jnp.stack([g * x[0] - om * x[1], om * x[0] + g * x[1]])

    return System(rhs=rhs, p=np.array([0.5]), param_names=("mu",), state_names=("x", "y"),
                  observables={"radius": lambda x, p: jnp.sqrt(x[0] ** 2 + x[1] ** 2)},
                  name="two Hopf points")


BT_BETA2 = -1.0


def bogdanov_takens_system() -> System:
    """The Bogdanov-Takens normal form (Kuznetsov 2004, sec. 8.4, s = -1):

        x' = y,   y' = beta1 + beta2 x + x^2 - x y,

    at beta2 = BT_BETA2 = -1, continued in beta1. The equilibrium (0, 0) at beta1 = 0 has
    trace 0 and determinant -beta2 = 1: a Hopf point (supercritical for s = -1); the stable
    cycles it sheds for beta1 < 0 grow until they meet the saddle (x = 1 - ..., 0) in a
    homoclinic orbit near beta1 = -6/25 beta2^2 (the leading-order curve P; the reference
    value for the tests is solved by shooting the saddle's manifolds,
    :func:`bt_homoclinic_beta1`). A planar system: no PD or NS, and no fold of the family on
    the way to the homoclinic orbit."""

    def rhs(x, p):
        b1, b2 = p[0], p[1]
        return jnp.stack([x[1], b1 + b2 * x[0] + x[0] ** 2 - x[0] * x[1]])

    return System(rhs=rhs, p=np.array([0.0, BT_BETA2]), param_names=("beta1", "beta2"),
                  state_names=("x", "y"),
                  observables={"x": lambda x, p: x[0], "y": lambda x, p: x[1]},
                  name="Bogdanov-Takens")


def bt_homoclinic_beta1(beta2: float = BT_BETA2) -> float:
    """beta1 of the homoclinic orbit of :func:`bogdanov_takens_system` by shooting: the
    branch of the saddle's unstable manifold that leaves towards the Hopf equilibrium is
    integrated until it crosses the line x = x_saddle (below the saddle, y < 0) again, and
    beta1 is solved (Brent) where that crossing falls on the saddle itself. An independent
    reference, no collocation involved."""
    import scipy.integrate
    import scipy.optimize

    def miss(b1: float) -> float:
        xs = (-beta2 + math.sqrt(beta2 * beta2 - 4.0 * b1)) / 2.0  # the saddle
        J = np.array([[0.0, 1.0], [beta2 + 2.0 * xs, -xs]])
        w, V = np.linalg.eig(J)
        v = np.real(V[:, int(np.argmax(w.real))])
        v = v if v[0] < 0 else -v  # towards the other equilibrium
        y0 = np.array([xs, 0.0]) + 1e-9 * v

        def f(t, z):
            return [z[1], b1 + beta2 * z[0] + z[0] ** 2 - z[0] * z[1]]

        def back(t, z):  # crossing x = xs again, coming back towards the saddle
            return z[0] - xs + 1e-12
        back.terminal, back.direction = True, 1
        sol = scipy.integrate.solve_ivp(f, (0.0, 200.0), y0, events=back, rtol=1e-12,
                                        atol=1e-14, method="DOP853")
        if not sol.t_events[0].size:
            return -1.0
        return float(sol.y_events[0][0][1])  # y there: 0 on the homoclinic orbit

    # the leading-order curve -6/25 beta2^2 = -0.24 brackets it with the Hopf value 0 side
    return float(scipy.optimize.brentq(miss, -0.24 * beta2 * beta2, -0.18 * beta2 * beta2,
                                       xtol=1e-12))


PITCH_NU = 0.0225  # (width of the band of transverse instability)^2
PITCH_RC2 = 1.05  # r^2 at its centre
PITCH_OMEGA = 2.0


def pitchfork_cycles_system(nu: float = PITCH_NU, rc2: float = PITCH_RC2) -> System:
    """A 3-D system with two branch points of cycles on one branch, near a fold of cycles:

        r' = r (mu + 2 r^2 - r^4),   theta' = OMEGA,   z' = (NU - (r^2 - RC2)^2) z - z^3,

    (x, y) = r (cos theta, sin theta), rotated by a fixed orthogonal 3 x 3 matrix. The cycles
    z = 0, mu = r^4 - 2 r^2 fold at r = 1 (mu = -1, LPC); their transverse multiplier
    exp((NU - (r^2 - RC2)^2) T) passes +1 where r^2 = RC2 -+ sqrt(NU) = 0.9 and 1.2, i.e.
    mu = -0.99 and -0.96 (pitchforks of cycles, z -> -z symmetry): two branch points (BP)
    on one branch, on either side of the fold and each within 0.04 of it in mu."""
    R = jnp.asarray(_orthogonal(3, 11))

    def rhs(x, p):
        mu = p[0]
        u = R.T @ x
        r2 = u[0] ** 2 + u[1] ** 2
        g = mu + 2.0 * r2 - r2 * r2
        k = nu - (r2 - rc2) ** 2
        du = jnp.stack([g * u[0] - PITCH_OMEGA * u[1], PITCH_OMEGA * u[0] + g * u[1],
                        k * u[2] - u[2] ** 3])
        return R @ du

    return System(rhs=rhs, p=np.array([0.0]), param_names=("mu",),
                  state_names=("x1", "x2", "x3"),
                  observables={"radius": lambda x, p: jnp.sqrt(jnp.sum((R.T @ x)[:2] ** 2)),
                               "z": lambda x, p: (R.T @ x)[2]},
                  name="pitchfork of cycles")


def pitchfork_bp_values(nu: float = PITCH_NU, rc2: float = PITCH_RC2) -> tuple[float, float]:
    """mu at the two branch points of :func:`pitchfork_cycles_system` (closed form)."""
    out = []
    for r2 in (rc2 - math.sqrt(nu), rc2 + math.sqrt(nu)):
        out.append(r2 * r2 - 2.0 * r2)
    return out[0], out[1]


# -------------------------------------------------------------------------------- equilibria
def saddle_node() -> System:
    """x' = mu - x^2, y' = -y + x^2: a fold at mu = 0, x = 0."""
    return System(rhs=lambda x, p: jnp.stack([p[0] - x[0] ** 2, -x[1] + x[0] ** 2]),
                  p=np.array([1.0]), param_names=("mu",), state_names=("x", "y"),
                  x_guess=np.array([1.0, 1.0]), name="saddle-node")


def pitchfork() -> System:
    """x' = mu x - x^3, y' = -y: the trivial branch x = 0 has a branch point at mu = 0."""
    return System(rhs=lambda x, p: jnp.stack([p[0] * x[0] - x[0] ** 3, -x[1]]),
                  p=np.array([-1.0]), param_names=("mu",), state_names=("x", "y"),
                  name="pitchfork")


S_HOPF_X = (-1.2, 0.8)  # x at the two Hopf points of s_shaped_hopf


def s_shaped_hopf() -> System:
    """x' = y, y' = mu - x^3 + x + (x - 0.8)(x + 1.2) y: equilibria (x, 0) with
    mu = x^3 - x (S-shaped, folds at x = +-1/sqrt 3), Jacobian [[0, 1], [1 - 3x^2, tr]],
    tr = (x - 0.8)(x + 1.2). Hopf points where tr = 0 and det = 3x^2 - 1 > 0: x = -1.2 on
    the lower branch (mu = -0.528) and x = 0.8 on the upper branch between the folds
    (mu = -0.288), frequencies sqrt(3x^2 - 1)."""

    def rhs(x, p):
        tr = (x[0] - S_HOPF_X[1]) * (x[0] - S_HOPF_X[0])
        return jnp.stack([x[1], p[0] - x[0] ** 3 + x[0] + tr * x[1]])

    return System(rhs=rhs, p=np.array([-1.0]), param_names=("mu",), state_names=("x", "y"),
                  x_guess=np.array([-1.3, 0.0]), name="S-shaped")


# ------------------------------------------------------------------------------------ Lorenz
LORENZ_SIGMA = 10.0
LORENZ_BETA = 8.0 / 3.0
LORENZ_RHO_H = LORENZ_SIGMA * (LORENZ_SIGMA + LORENZ_BETA + 3) / (LORENZ_SIGMA - LORENZ_BETA - 1)


def lorenz() -> System:
    """x' = sigma (y - x), y' = x (rho - z) - y, z' = x y - beta z; parameters (sigma,
    rho, beta); the equilibrium guess is C+ = (sqrt(beta (rho - 1)), same, rho - 1)."""

    def rhs(x, p):
        s, r, b = p[0], p[1], p[2]
        return jnp.stack([s * (x[1] - x[0]), x[0] * (r - x[2]) - x[1], x[0] * x[1] - b * x[2]])

    rho = 20.0
    c = math.sqrt(LORENZ_BETA * (rho - 1))
    return System(rhs=rhs, p=np.array([LORENZ_SIGMA, rho, LORENZ_BETA]),
                  param_names=("sigma", "rho", "beta"), state_names=("x", "y", "z"),
                  x_guess=np.array([c, c, rho - 1]), state_scale=np.array([10.0, 10.0, 20.0]),
                  observables={"x": lambda x, p: x[0], "z": lambda x, p: x[2]},
                  name="Lorenz")


# ---------------------------------------------------------------------------------------
# Closed-form unstable cycle for the sensitivity and design tests.
#
# The subcritical Hopf normal form in polar form r' = (mu - a) r + l1 r^3, theta' = omega,
# with a stable third direction driven by r^2, embedded by a fixed invertible linear map:
# for a > mu and l1 > 0 the equilibrium is stable and surrounded by the unstable cycle of
# radius h = sqrt((a - mu) / l1) (Kuznetsov 2004, sec. 3.4), read out as the first normal-form
# coordinate ("gap_deviation"). The Hopf point along a is a_H = mu.
# ---------------------------------------------------------------------------------------
_NF_M = np.array([[1.0, 0.3, -0.2], [-0.4, 1.2, 0.1], [0.25, 0.5, 0.9]])
_NF_MINV = np.linalg.inv(_NF_M)
NF_NAMES = ("mu", "a", "omega", "l1", "b")
NF_DESIGN = {"mu": 1.0, "a": 1.5, "omega": 2.0, "l1": 2.0, "b": 0.7}


def _nf_xi(x):
    return jnp.asarray(_NF_MINV) @ x


def _nf_rhs(x, p):
    mu, a, om, l1, b = p[0], p[1], p[2], p[3], p[4]
    u, v, w = _nf_xi(x)
    r2 = u * u + v * v
    du = (mu - a) * u - om * v + l1 * u * r2
    dv = om * u + (mu - a) * v + l1 * v * r2
    dw = -w + b * r2
    return jnp.asarray(_NF_M) @ jnp.stack([du, dv, dw])


def _nf_gap(x, p):
    return _nf_xi(x)[0]


def _nf_current(x, p):
    return _nf_xi(x)[1]


def normal_form_system(**values: float) -> System:
    """The embedded normal form at NF_DESIGN updated by ``values``."""
    d = dict(NF_DESIGN, **values)
    return System(rhs=_nf_rhs, p=np.array([d[n] for n in NF_NAMES]), param_names=NF_NAMES,
                  state_names=("x1", "x2", "x3"),
                  observables={"gap_deviation": _nf_gap, "current": _nf_current}, name="hopf-nf")


def nf_amplitude(mu: float, a: float, l1: float) -> float:
    """Closed-form radius of the unstable cycle."""
    return math.sqrt((a - mu) / l1)


# ------------------------------------------------------------------ clamped oscillator
# x'' = -omega^2 x - 2 zeta omega x' + a (max(i, 0) - i0),  i' = -kc (i - i0) - g x',
# the current i held at 0 while it would fall below (the maglev models' clamp, in small).
OSC_NAMES = ("omega", "zeta", "a", "i0", "kc", "g")
OSC_P = np.array([2.0 * math.pi, 0.05, 20.0, 1.0, 4.0, 6.0])
OSC_UPPER = 0.25  # the upper limit of x; the lower one is far (-2)
OSC_LOWER = -2.0
OSC_SCALE = np.array([0.01, 0.1, 0.01])


def _osc_rate(x, p):
    """The free current rate -kc (i - i0) - g x'."""
    return -p[4] * (x[2] - p[3]) - p[5] * x[1]


def _osc_field(x, p, i_force):
    return jnp.stack([x[1], -p[0] ** 2 * x[0] - 2.0 * p[1] * p[0] * x[1]
                      + p[2] * (i_force - p[3])])


def clamped_oscillator_limited_rhs(x, p):
    """The limited vector field (force from max(i, 0), di/dt held at 0 while i <= 0 and
    falling), as the simulator integrates it."""
    from maglev_match.maglev.limits import clamp_current, hold_current_rate

    di = hold_current_rate(x[2], _osc_rate(x, p))
    return jnp.concatenate([_osc_field(x, p, clamp_current(x[2])), di[None]])


def clamped_oscillator_limited() -> System:
    return System(rhs=clamped_oscillator_limited_rhs, p=OSC_P.copy(), param_names=OSC_NAMES,
                  state_names=("x", "v", "i"), x_guess=np.array([0.0, 0.0, OSC_P[3]]),
                  state_scale=OSC_SCALE, name="clamped oscillator (limited)")


def oscillator_limit_events(x, p):
    """x - lower, upper - x: negative is a collision."""
    return jnp.stack([x[0] - OSC_LOWER, OSC_UPPER - x[0]])


def _osc_hybrid_rhs(x, p, s):
    held = s[0] > 0.5
    free = jnp.concatenate([_osc_field(x, p, x[2]), _osc_rate(x, p)[None]])
    hold = jnp.concatenate([_osc_field(x, p, 0.0), jnp.zeros(1)])
    return jnp.where(held, hold, free)


def _osc_guards(x, p, s):
    # free: the current; held: minus the free rate at i = 0
    rate0 = p[4] * p[3] - p[5] * x[1]
    return jnp.reshape(jnp.where(s[0] > 0.5, -rate0, x[2]), (1,))


def _osc_project(x, p, s):
    return jnp.where(s[0] > 0.5, x.at[2].set(0.0), x)


def clamped_oscillator(**values: float):
    """The clamped oscillator as a :class:`~maglev_match.dynamics.hybrid.HybridSystem`."""
    from maglev_match.dynamics.hybrid import HybridSystem

    p = OSC_P.copy()
    for k, v in values.items():
        p[OSC_NAMES.index(k)] = v
    return HybridSystem(rhs=_osc_hybrid_rhs, guards=_osc_guards, project=_osc_project,
                        n_switches=1, p=p, param_names=OSC_NAMES,
                        state_names=("x", "v", "i"), state_scale=OSC_SCALE,
                        name="clamped oscillator")


def damped_first_overshoot(d: float, zeta: float) -> float:
    """The first maximum of x'' + 2 zeta omega x' + omega^2 x = 0 from x(0) = -d, x'(0) = 0:
    d exp(-zeta pi / sqrt(1 - zeta^2)) (at t = pi / omega_d)."""
    return d * math.exp(-zeta * math.pi / math.sqrt(1.0 - zeta * zeta))


# --------------------------------------------------------- saturated planar oscillator
SAT_NAMES = ("zeta", "k")
SAT_P = np.array([0.1, 1.0])


def _sat_rhs(x, p, s):
    hi, lo = s[0] > 0.5, s[1] > 0.5
    sat = jnp.where(hi, 1.0, jnp.where(lo, -1.0, x[1]))
    return jnp.stack([x[1], -x[0] - 2.0 * p[0] * x[1] + p[1] * sat])


def _sat_guards(x, p, s):
    y = x[1]
    return jnp.stack([jnp.where(s[0] > 0.5, y - 1.0, 1.0 - y),
                      jnp.where(s[1] > 0.5, -1.0 - y, y + 1.0)])


def saturated_oscillator(**values: float):
    """x' = y, y' = -x - 2 zeta y + k sat(y), sat = clip(y, -1, 1), as a hybrid system with
    two switches (y saturated above, below). With k > 2 zeta the origin is unstable and a
    stable limit cycle crosses the linear band |y| < 1 and both saturated regions. The
    vector field is continuous, so every saltation matrix has determinant 1 and the
    non-trivial Floquet multiplier is exp(int div f dt) = exp((k - 2 zeta) T_lin -
    2 zeta T_sat) (Liouville), with T_lin, T_sat the times spent in and out of the band."""
    from maglev_match.dynamics.hybrid import HybridSystem

    p = SAT_P.copy()
    for k, v in values.items():
        p[SAT_NAMES.index(k)] = v
    return HybridSystem(rhs=_sat_rhs, guards=_sat_guards, n_switches=2, p=p,
                        param_names=SAT_NAMES, state_names=("x", "y"),
                        state_scale=np.array([1.0, 1.0]),
                        observables={"x": lambda x, p: x[0], "y": lambda x, p: x[1]},
                        name="saturated oscillator")


def saturated_oscillator_shooting(zeta: float, k: float) -> tuple[float, float]:
    """(period, amplitude) of the saturated oscillator's limit cycle by an independent
    method: SciPy's DOP853 on the continuous field (np.clip, no events at the kinks; the
    step control shrinks the steps there) and Brent's method on the return map of the
    section y = 0 crossed downwards (where x is largest)."""
    import scipy.optimize
    from scipy.integrate import solve_ivp

    def f(t, z):
        return [z[1], -z[0] - 2.0 * zeta * z[1] + k * min(max(z[1], -1.0), 1.0)]

    def section(t, z):
        return z[1] if t > 0.5 else -1.0  # the start (on the section) does not count

    section.direction = -1.0
    section.terminal = True

    def ret(x0: float) -> tuple[float, float]:
        sol = solve_ivp(f, (0.0, 100.0), [x0, 0.0], method="DOP853", rtol=1e-13,
                        atol=1e-13, events=section, max_step=0.01)
        return float(sol.y_events[0][0][0]), float(sol.t_events[0][0])

    xs = scipy.optimize.brentq(lambda x0: ret(x0)[0] - x0, 1.0, 20.0, xtol=1e-14)
    return ret(xs)[1], xs
# ------------------------------------------------------------------------ delay equations
def _state_signal(x, p):
    return x


def _x(x, p):
    return x[0]


def _linear_dde_rhs(x, xd, p):
    return -p[0] * xd[0]


def linear_dde(a: float = 2.0, tau: float = 0.5) -> DelayDifferentialSystem:
    """x' = -a x(t - tau). Characteristic equation lambda = -a exp(-lambda tau), so
    lambda tau exp(lambda tau) = -a tau and lambda = W_k(-a tau) / tau (Lambert W, branch k);
    a pair crosses the imaginary axis at i a when a tau = pi / 2 (Hale & Verduyn Lunel 1993,
    ch. 5)."""
    return DelayDifferentialSystem(rhs=_linear_dde_rhs, signals=(_state_signal,),
                                   delays=("tau",), p=np.array([a, tau]),
                                   param_names=("a", "tau"), state_names=("x",),
                                   observables={"x": _x}, name="linear-dde")


def _hutchinson_rhs(x, yd, p):
    return p[0] * x * (1.0 - yd[0] / p[1])


def hutchinson(r: float = 1.0, K: float = 1.0, tau: float = 1.0) -> DelayDifferentialSystem:
    """The delayed logistic equation x' = r x (1 - x(t - tau) / K) (Hutchinson 1948):
    linearised at x = K it is u' = -r u(t - tau), so a Hopf bifurcation at r tau = pi / 2 with
    frequency r (period 4 tau); supercritical (e.g. Hassard, Kazarinoff & Wan 1981)."""
    return DelayDifferentialSystem(rhs=_hutchinson_rhs, signals=(_state_signal,),
                                   delays=("tau",), p=np.array([r, K, tau]),
                                   param_names=("r", "K", "tau"), state_names=("x",),
                                   x_guess=np.array([K]), observables={"x": _x},
                                   name="hutchinson")


def _mackey_glass_rhs(x, yd, p):
    beta, gamma, n = p[0], p[1], p[2]
    y = yd[0]
    return beta * y / (1.0 + y**n) - gamma * x


def mackey_glass(beta: float = 2.0, gamma: float = 1.0, n: float = 9.65,
                 tau: float = 0.5) -> DelayDifferentialSystem:
    """The Mackey-Glass equation x' = beta x(t - tau) / (1 + x(t - tau)^n) - gamma x
    (Mackey & Glass 1977) with the equilibrium x = 1 (beta = 2 gamma); with n = 9.65 its
    cycles, born at a Hopf point near tau = 0.497, period-double as tau grows (the route to
    the chaos of the classic tau = 2 example; Duruisseaux & Humphries 2022)."""
    return DelayDifferentialSystem(rhs=_mackey_glass_rhs, signals=(_state_signal,),
                                   delays=("tau",), p=np.array([beta, gamma, n, tau]),
                                   param_names=("beta", "gamma", "n", "tau"),
                                   state_names=("x",), x_guess=np.array([1.0]),
                                   observables={"x": _x}, name="mackey-glass")


# ------------------------------------------------------------------- FitzHugh-Nagumo
def fitzhugh_nagumo(eps: float = 0.08, b: float = 0.8) -> System:
    """x' = x - x^3 / 3 - y, y' = eps (x + a - b y): symmetric under (x, y, a) -> (-x, -y,
    -a), two subcritical Hopf points at a = +-a_H joined by one family of cycles that turns
    back in a just beyond each Hopf point (a fold of cycles, then the canard explosion to
    the relaxation oscillation, where the multipliers lose all accuracy)."""
    def rhs(x, p):
        a = p[0]
        return jnp.array([x[0] - x[0] ** 3 / 3 - x[1], eps * (x[0] + a - b * x[1])])

    return System(rhs=rhs, p=np.array([0.0]), param_names=("a",), state_names=("x", "y"),
                  x_guess=np.array([0.0, 0.0]))
