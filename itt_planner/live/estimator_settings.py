"""The estimator's noise levels, gates and limits (`estimate.StateEstimator`), in SI units.

Apart from the estimator so that its module stays about the filter; `estimate` imports it
from here, as the engine and the tests do from `estimate`.
"""

from __future__ import annotations

from dataclasses import dataclass

from itt_planner.model.wprime import WPrimeModel


@dataclass(frozen=True)
class EstimatorSettings:
    """Noise levels, gates and limits of the estimator (SI units).

    Attributes:
        gps_std_m: GPS 1-sigma used when a fix carries none (bike GPS: 3-5 m).
        speed_std_mps: wheel-speed noise.
        accel_std_mps2: process noise, the rider's unmodelled acceleration.
        odometry_drift: dead-reckoning error as a fraction of the distance travelled
            (wheel circumference error, the wheel's path is not the centre line).
        gate_sigma: a GPS `s` innovation beyond this many sigmas is an outlier ...
        gate_floor_m: ... unless it is smaller than this (ordinary GPS noise always passes).
        off_course_m: a fix farther than this beyond the road edge is off the course.
        search_margin_m: the local search window is predicted `s` +/- (this + 4 sigma).
        lost_after: this many consecutive rejected fixes trigger a global re-acquisition.
        speed_stale_s, gps_stale_s, speed_decay_s: with neither a wheel speed nor a fix
            this recent, the speed decays with this time constant instead of running on.
        gps_interval_factor: ... nor a fix within this many times the 90th percentile of
            the last `gps_intervals_kept` intervals between fixes, if that is longer than
            `gps_stale_s`: a smart recorder writes a fix every 15-27 s on a straight (a
            2009 Garmin TCX in stravalib's tests), and a rider riding on between them at
            8 m/s decayed to 0.1 m/s before each (fallback advice for a stopped rider).
        power_hold_s: a reading holds this long at most (smart recording: 1-8 s steps), then 0.
        max_power_w: readings above this are spikes.
        max_speed_mps: wheel speeds above this are glitches.
        max_lag_s: a GPS fix or wheel speed older than the filter time by more than this
            is dropped (samples of different topics may interleave slightly out of
            order); a power reading is not (the W' balance has its own time axis).
        catchup_mps: how fast the published `s` may catch up with the filter, beyond
            the speed itself.
        lateral_tau_s: time constant of the lateral offset low-pass: bike GPS cannot
            place a rider within a lane (its 3-5 m error is a slowly wandering bias), so
            `n` is only a slow, conservative estimate ...
        lateral_edge_m: ... kept this far inside the road edges (a noisy `n` at the
            edge would make the planner brake for a road edge the rider is not at).
        global_window_m: a local search window wider than this (after a long gap)
            becomes a global search that prefers the predicted `s`.
        start_reach_m: a first fix (or a re-acquisition before this far along) this near
            the course's start is at the start, not at a pass elsewhere (a loop's finish).
        confirm_m: until the rider has ridden this far on from where the first fix
            placed it, a re-acquisition looks for the start first ...
        reacquire_back_m: ... and, this far behind the published `s`, moves it back
            (`estimate`'s docstring); nearer, the published `s` slows until passed.
        wprime_model: E9 variant.
    """

    gps_std_m: float = 4.0
    speed_std_mps: float = 0.3
    accel_std_mps2: float = 0.7
    odometry_drift: float = 0.03
    gate_sigma: float = 4.0
    gate_floor_m: float = 20.0
    off_course_m: float = 30.0
    search_margin_m: float = 60.0
    lost_after: int = 5
    speed_stale_s: float = 3.0
    gps_stale_s: float = 10.0
    gps_interval_factor: float = 1.5
    gps_intervals_kept: int = 30
    speed_decay_s: float = 2.0
    power_hold_s: float = 10.0
    max_power_w: float = 3000.0
    max_speed_mps: float = 35.0
    max_lag_s: float = 2.0
    catchup_mps: float = 5.0
    lateral_tau_s: float = 10.0
    lateral_edge_m: float = 1.0
    global_window_m: float = 2000.0
    start_reach_m: float = 50.0
    confirm_m: float = 200.0
    reacquire_back_m: float = 100.0
    wprime_model: WPrimeModel = WPrimeModel.SKIBA
