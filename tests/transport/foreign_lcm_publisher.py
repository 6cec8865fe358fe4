#!/usr/bin/env python3
"""A foreign publisher for python_subscriber_test.sh (inside its private network
namespace only): after 1 s, one datagram on TISSUE_SURFACE_MESH that is not a
surface_mesh, and one sim_stats with a NaN real-time factor.
Args: PYTHON_TYPES_DIR"""
import sys
import time

import lcm

sys.path.insert(0, sys.argv[1])
from tissue import sim_stats  # noqa: E402  (the generated types are found through argv)

lc = lcm.LCM("udpm://239.255.76.67:7667?ttl=0")
time.sleep(1.0)
lc.publish("TISSUE_SURFACE_MESH", b"not a surface mesh")
m = sim_stats()
m.time_s = 0.5
m.real_time_factor = float("nan")
lc.publish("TISSUE_SIM_STATS", m.encode())
