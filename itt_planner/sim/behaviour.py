"""The simulated rider's imperfections and controller gains (`RiderBehaviour`), and what
the planner believes about grip for such a rider (`planning_conditions`)."""

from __future__ import annotations

from dataclasses import dataclass

from itt_planner.model.conditions import Conditions


@dataclass(frozen=True)
class RiderBehaviour:
    """The simulated rider's imperfections: lag and noise in following a power target,
    and the gains of the path-following controller (steering by lean, section notes in
    `itt_planner.sim.step`).

    Attributes:
        power_lag_s: first-order lag of the delivered power behind the target.
        power_noise: relative 1-sigma of the rider's power wander ...
        power_noise_tau_s: ... and its correlation time.
        brake_margin_mps: the rider brakes when faster than the advised speed by this.
        brake_lookahead_s: ... looking this far ahead along the advised profile.
        w_reserve: below this fraction of W' the rider cannot exceed CP (exhausted).
        roll_omega_radps: bandwidth of the lean loop (a gentler lean needs less
            counter-steer, which the tyres must carry too).
        grip_lateral: fraction of `mu_y g` the rider uses in a steady turn (the rest is
            headroom for the lean loop); sets the corner speed the rider brakes for.
        grip_brake: fraction of `mu_x g` the rider plans to brake at when looking ahead.
        brake_gain: braking command `-W_n` per m/s over the brake speed.
    """

    power_lag_s: float = 0.8
    power_noise: float = 0.03
    power_noise_tau_s: float = 5.0
    brake_margin_mps: float = 1.0
    brake_lookahead_s: float = 0.5
    w_reserve: float = 0.005
    k_lateral_ps: float = 0.3
    k_heading_ps: float = 1.0
    roll_omega_radps: float = 3.0
    steer_preview_s: float = 0.8
    grip_lateral: float = 0.92
    grip_brake: float = 0.5
    brake_gain: float = 0.5


def planning_conditions(conditions: Conditions = Conditions(),
                        behaviour: RiderBehaviour = RiderBehaviour()) -> Conditions:
    """What the planner believes when the truth is `conditions` and the rider `behaviour`.

    The road and the air as they are, with the lateral grip the rider really uses in a
    steady turn (`behaviour.grip_lateral` of `mu_y`). Why: a plan cornering at 100 % of
    `mu_y` is one this rider cannot follow (it keeps the rest as headroom for leaning
    in and out), so it is not the optimum for this rider; with these conditions the
    belief equals the truth in `nominal`, and the plan's finish time is the optimum
    for the grip the rider uses. Solve the full-course plan with them
    (`simulate_ride`'s engine plans its horizon with them too).
    """
    return conditions.with_lateral_grip(behaviour.grip_lateral)
