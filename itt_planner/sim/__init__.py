"""Stage 8, the virtual rider: a closed-loop simulation of a rider following (or not) the
engine's advice on the 3D model, and the demo ride logs made from it.

    hairpin     the short technical test course of the closed-loop tests
    sensors     simulated GPS, wheel-speed and power sensors; smart recording's thinning
    scenarios   how the truth differs from the belief, and the rider's policy
    behaviour   the rider's lag, noise and controller gains; the grip the planner assumes
    step        one time step of the 3D model under the rider's controller (CasADi)
    reference   the profile and line the rider follows (plan or advice)
    loop        `simulate_ride`: sensors -> engine -> rider -> model, step by step
    compare     the three policies on one truth (`itt-planner simulate`)
    demo_bags   a simulated ride written as an MCAP ride log
"""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
