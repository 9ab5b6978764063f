"""Identify the learning channel of vehicles on their own controller: the table of docs/closed_loop.md.

Run from anywhere: ``python examples/identify_a_channel.py [SECONDS] [VEHICLES]``. Needs the optional
simulator (``pip install 'ilcdob[rotorpy]'``). Each vehicle flies rotorpy's SE3 controller with 0.5 mm of
position noise: rotorpy's crazyflie and hummingbird with rotorpy's gains, and "lab-quad", a 1.4 kg quad
with 25 cm arms and gains of its own (an airframe rotorpy does not ship). Per vehicle, channel (position
offset, acceleration feed-forward) and axis, two chirp flights of SECONDS (default 30) are fitted
(ilcdob.validation.channel_id) and the fit's static gain is printed beside the loop's (1 on the position
channel, 1/kp on the acceleration channel). VEHICLES is a comma-separated subset (default all three).
"""

import sys

import numpy as np

from ilcdob.validation.channel_id import identify_channel
from ilcdob.vehicles.rotorpy_vehicle import RotorpyVehicle, shipped_airframe

seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 30.0
base = shipped_airframe("hummingbird")
lab_quad = {**base, "mass": 1.4, "Ixx": 0.012, "Iyy": 0.012, "Izz": 0.022,
            "rotor_pos": {k: 1.5 * np.asarray(v) for k, v in base["rotor_pos"].items()}}
fleet = {"crazyflie": (None, None), "hummingbird": (None, None),
         "lab-quad": (lab_quad, ((4.0, 4.0, 10.0), (3.0, 3.0, 7.0)))}
names = sys.argv[2].split(",") if len(sys.argv) > 2 else list(fleet)

print("vehicle      channel       axis  structure  estimation %  held-out %  static gain (fit / loop)")
for name in names:
    airframe, gains = fleet[name]
    kp = np.array(gains[0]) if gains else np.array([6.5, 6.5, 15.0])  # rotorpy's SE3 position gains

    def make(vehicle, seed, airframe=airframe, gains=gains):
        return RotorpyVehicle(vehicle, 0.01, noise_std=5e-4, seed=seed, airframe=airframe, position_gains=gains)

    for channel in ("position", "acceleration"):
        for i, axis in enumerate("xyz"):
            fit = identify_channel(make, name, 0.01, channel, axis, duration=seconds)
            loop = 1.0 if channel == "position" else 1.0 / kp[i]
            gain = fit.plant.num[-1] / fit.plant.den[-1]
            print(f"{name:12s} {channel:13s} {axis:4s}  {fit.structure.n_poles}p{fit.structure.n_zeros}z       "
                  f"{fit.fit_estimation:8.2f}   {fit.fit_validation:8.2f}    {gain:.4f} / {loop:.4f}", flush=True)
