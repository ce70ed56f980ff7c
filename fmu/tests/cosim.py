"""Co-simulation of the shimmy FMU (the controller and monitor) with the independent NumPy/SciPy
plant of host-sim/reference/plant_scipy.py, stepped by fmpy at the 1 kHz control period."""
import importlib.util
import math
import pathlib
import shutil

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave
from scipy.integrate import solve_ivp

ROOT = pathlib.Path(__file__).resolve().parents[2]
DT_S = 1e-3


def load_reference():
    path = ROOT / "host-sim" / "reference" / "plant_scipy.py"
    spec = importlib.util.spec_from_file_location("plant_scipy", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def quantise(x, q):
    return np.round(x / q) * q if q > 0 else x


def wrap_pi(a):
    """As the simulator's wrap_pi (f64::rem_euclid): math.fmod keeps the sign of a zero, so a
    reading that rounds to zero from below is -0.0 there too (np.mod would give +0.0, and the
    supervisor's bit-identical stuck check tells them apart)."""
    w = math.fmod(a, 2 * np.pi)
    if w < 0.0:
        w += 2 * np.pi
    return w - 2 * np.pi if w > np.pi else w


class Sensors:
    """The simulator's sensor models without their random noise (host-sim/src/model/sensors.rs
    with `sensor_noise = False`): encoders quantised to 2 pi / 2^bits with one sample of delay,
    the speed as it is, the coil current through the shunt ADC (12 bits over the full scale)."""

    def __init__(self, vehicle):
        bits = vehicle.get("sensors.encoder_bits")
        self.lsb = 2 * np.pi / 2 ** bits
        self.full_scale_a = vehicle.get("sensors.current_full_scale_a")
        self.current_q = self.full_scale_a / 2 ** 12
        self.scale = 1.0 + vehicle.get("sensors.speed_scale_error")
        self.delayed = None

    def read(self, psi_l, psi_r, speed_mps, coil_a):
        angles = self.delayed if self.delayed is not None else (psi_l, psi_r)
        self.delayed = (psi_l, psi_r)
        enc = [float(np.float32(wrap_pi(quantise(a, self.lsb)))) for a in angles]
        current = float(np.clip(quantise(coil_a, self.current_q), 0.0, self.full_scale_a))
        return enc[0], enc[1], max(self.scale * speed_mps, 0.0), current


class Controller:
    """The FMU as a co-simulation slave: set the raw sensor signals at t, step 1 ms, read the
    command (computed from the inputs at t, applied over [t, t + 1 ms))."""

    OUTPUTS = ["current_cmd_a", "zeta_data", "sigma_zeta_data", "freq_hz", "zeta_model",
               "speed_margin_mps"]
    INT_OUTPUTS = ["supervisor_mode", "warning_level"]

    def __init__(self, fmu_path, vehicle="nominal"):
        self.md = read_model_description(str(fmu_path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.dir = extract(str(fmu_path))
        self.slave = FMU3Slave(guid=self.md.guid, unzipDirectory=self.dir,
                               modelIdentifier=self.md.coSimulation.modelIdentifier,
                               instanceName="shimmy")
        self.slave.instantiate()
        self.slave.setString([self.vr["vehicle"]], [vehicle])
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def step(self, t, psi_l, psi_r, speed_mps, coil_a):
        """`coil_a=None` leaves the coil-current input at its value (its start value: not
        measured)."""
        vr = self.vr
        names, values = ["psi_l_rad", "psi_r_rad", "speed_mps"], [psi_l, psi_r, speed_mps]
        if coil_a is not None:
            names.append("coil_current_a")
            values.append(coil_a)
        self.slave.setFloat64([vr[n] for n in names], values)
        self.slave.doStep(t, DT_S)
        out = dict(zip(self.OUTPUTS, self.slave.getFloat64([vr[n] for n in self.OUTPUTS])))
        out.update(zip(self.INT_OUTPUTS, self.slave.getInt32([vr[n] for n in self.INT_OUTPUTS])))
        return out

    def close(self):
        self.slave.terminate()
        self.slave.freeInstance()
        shutil.rmtree(self.dir, ignore_errors=True)


def cosimulate(fmu_path, vehicle, speed_kmh, yaw0_deg, duration_s, fmu_vehicle="nominal"):
    """Closed loop: reference plant of `vehicle` (a shimmy_sim.Vehicle) at constant speed from an
    in-phase wheel-yaw kick, FMU controller with the parameter `vehicle = fmu_vehicle`.
    Returns per-sample arrays (t_s, psi_l_rad, current_cmd_a, ...) and the final FMU outputs."""
    ref = load_reference()
    p, m = vehicle.plant(), vehicle.damper()
    v = speed_kmh / 3.6
    sensors = Sensors(vehicle)
    ctl = Controller(fmu_path, fmu_vehicle)
    n = int(round(duration_s / DT_S))
    x = np.zeros(13)
    x[0] = x[1] = np.radians(yaw0_deg)
    rows = {"t_s": [], "psi_l_rad": [], "current_cmd_a": [], "warning_level": [], "supervisor_mode": [], "coil_a": [], "psi_r_rad": []}
    try:
        for k in range(n):
            t = k * DT_S
            out = ctl.step(t, *sensors.read(x[0], x[1], v, x[10]))
            rows["t_s"].append(t)
            rows["psi_l_rad"].append(x[0])
            rows["current_cmd_a"].append(out["current_cmd_a"])
            rows["warning_level"].append(out["warning_level"])
            rows["supervisor_mode"].append(out["supervisor_mode"])
            rows["coil_a"].append(x[10])
            rows["psi_r_rad"].append(x[1])
            sol = solve_ivp(ref.rhs, (t, t + DT_S), x, method="RK45", rtol=1e-8, atol=1e-11,
                            args=(p, m, v, out["current_cmd_a"]))
            x = sol.y[:, -1]
    finally:
        ctl.close()
    return {k: np.array(a) for k, a in rows.items()}, out
