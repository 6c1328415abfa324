"""Exact integrators of the adaptation time courses.

Every time course in the models is integrated *exactly* for a goal held constant
over the step (zero-order hold of the frame's adaptation goal), so results do not
depend on the frame rate and stay bounded for any step from 1 ms to hours.

>>> round(exponential_step(0.0, 1.0, 0.1, 0.1), 6)     # one time constant
0.632121
>>> bleaching_step(1.0, 1e6, 3600.0, 16.0, 400.0) < 1e-4   # an hour in bright light
True
"""

from __future__ import annotations

import math


def exponential_step(value: float, goal: float, dt: float, t0: float) -> float:
    """First-order low-pass toward ``goal`` over ``dt`` seconds, time constant ``t0``.

    Exact solution of dA/dt = (G - A)/t0 with G constant: the paper's filter
    with F = 1 - exp(-T/t0) (Pattanaik 2000, Sec. 4.1.2, Fig. 6).
    """
    if dt <= 0.0:
        return value
    f = -math.expm1(-dt / t0)  # 1 - exp(-dt/t0), accurate for dt << t0
    return value + f * (goal - value)


def bleaching_step(bleach: float, goal: float, dt: float, k_half: float, tau: float) -> float:
    """Exact pigment kinetics over ``dt`` seconds (Pattanaik 2000, Eq. 7 as an ODE).

    Eq. 7's discrete step B += K(B) - J(G, B) with J = T*B*G/k, K = T*(1-B)/tau
    is the explicit Euler step of
        dB/dt = -B*G/k + (1 - B)/tau,
    which is linear in B: with r = G/k + 1/tau and B_inf = (1/tau)/r,
        B(t + dt) = B_inf + (B(t) - B_inf) * exp(-r*dt).
    B_inf = k/(k + tau*G) is Hunt's static B (Eq. 6) for k/tau = 0.04 (rods)
    and 2e6 (cones). The result stays in [0, 1] for any G >= 0 and dt >= 0,
    where the explicit step goes negative once dt*G/k > 1.
    """
    goal = max(goal, 0.0)
    r = goal / k_half + 1.0 / tau
    b_inf = (1.0 / tau) / r
    if dt <= 0.0:
        return bleach
    return b_inf + (bleach - b_inf) * math.exp(-r * dt)
