"""The one conversion between the code's SI speeds and the km/h people read at the edges.

Everything inside the project is SI (m, s, W, J, rad); CLI options, JSON fields named
`*_kmh`, reports and Rerun panels show speeds in km/h. Angles at the edges use
`math.degrees`/`math.radians`.
"""

from __future__ import annotations

#: km/h per m/s: multiply a speed in m/s to show it, divide a speed read in km/h.
MPS_TO_KMH = 3.6
