#!/usr/bin/env python3
"""Reference implementation of the shimmy plant in NumPy/SciPy, written from
docs/plant-model.md independently of the Rust code.

Used by `shimmy-sim reference-bench` as (1) a speed reference (solve_ivp for the time-domain run,
every method of [case] methods at the simulator's own rtol and per-state atol, the fastest being
the peer; one batched numpy.linalg.eigvals call for the eigenvalue sweep) and (2) a second
implementation whose trajectory and eigenvalues the Rust results must match.

usage: plant_scipy.py CASE.toml RESULT.json
       plant_scipy.py truck CASE.toml RESULT.txt
       plant_scipy.py trailer CASE.toml RESULT.txt
       plant_scipy.py dual CASE.toml RESULT.txt
CASE.toml holds [plant] (parameter names as in core/src/vehicles/car/params.rs), [damper] (Spencer model,
already scaled), [case] (speed, current, initial yaw, duration, sample times, sweep speeds) and
optionally [ramp] (the demo's drive with a simple current law instead of the controller, for the
closed-loop speed comparison; see rhs_ramp).

The `truck` form is the mining dump truck of docs/mining-truck.md, written from that document:
CASE.toml holds [truck] (the physical inputs: masses, inertias, tyre, strut gas charge, steering
cylinders, loads; names as in core/src/vehicles/truck/params.rs, the strut's with an `hps_` prefix) and
[case] speeds_mps; RESULT.txt gets one line `speed re im` per eigenvalue (numpy.linalg.eigvals).

The `trailer` form is the 2-DOF trailer on a compliant hitch of docs/trailer.md, written from
that document: CASE.toml holds [trailer] (names as in core/src/vehicles/trailer/params.rs) and [case] speeds_mps
and damper_nspm (the sway damper's coefficient); RESULT.txt gets one line `speed re im` per
eigenvalue.

The `dual` form is the dual-front-axle truck of docs/dual-axle-truck.md, written from that
document: CASE.toml holds [dual] (names as in core/src/vehicles/dual_axle/params.rs) and [case] speeds_mps;
RESULT.txt as for the truck.
"""
import json
import sys
import time
import tomllib

import numpy as np
from scipy.integrate import solve_ivp


def tyre_force(p, a):
    d = p["mu"] * p["f_z"]
    b = p["c_a"] / (p["c_s"] * d)
    return d * np.sin(p["c_s"] * np.arctan(b * a))


def rhs(t, x, p, m, v, u_cmd, tq=(0.0, 0.0)):
    psi_l, psi_r, phi, th, dpsi_l, dpsi_r, dphi, dth, a_l, a_r, u, y, z = x
    h = p["i_p"] * v / p["r"]
    f_l, f_r = tyre_force(p, a_l), tyre_force(p, a_r)
    # Spencer modified Bouc-Wen damper on the track rod.
    xd = 0.5 * p["l_t"] * (psi_l + psi_r)
    vd = 0.5 * p["l_t"] * (dpsi_l + dpsi_r)
    u_cmd = min(max(u_cmd, 0.0), m["u_max"])
    du = -m["eta"] * (u - u_cmd)
    alpha = m["alpha_a"] + m["alpha_b"] * u
    c0 = m["c0a"] + m["c0b"] * u
    c1 = m["c1a"] + m["c1b"] * u
    dy = (alpha * z + c0 * vd + m["k0"] * (xd - y)) / (c0 + c1)
    rel = vd - dy
    n = m["n"]
    dz = (m["a_bw"] * rel - m["beta"] * rel * abs(z) ** n
          - m["gamma"] * abs(rel) * abs(z) ** (n - 1) * z)
    f_d = c1 * dy + m["k1"] * (xd - m["x0"])
    tq_d = 0.5 * p["l_t"] * f_d
    trail = p["e"] + p["t_p"]
    kd = p["k_d"] * (th / p["i_s"] - psi_l)
    ktr = p["k_tr"] * (psi_l - psi_r)
    return [
        dpsi_l, dpsi_r, dphi, dth,
        (-p["c_k"] * dpsi_l - ktr + kd - trail * f_l - h * dphi - tq_d + tq[0]) / p["i_k"],
        (-p["c_k"] * dpsi_r + ktr - trail * f_r - h * dphi - tq_d + tq[1]) / p["i_k"],
        (-p["c_phi"] * dphi - p["k_phi"] * phi + p["h_r"] * (f_l + f_r)
         + h * (dpsi_l + dpsi_r)) / p["i_phi"],
        (-p["c_sw"] * dth - kd / p["i_s"]) / p["j_sw"],
        (v * (psi_l - a_l) + p["e"] * dpsi_l - p["h_r"] * dphi) / p["sigma"],
        (v * (psi_r - a_r) + p["e"] * dpsi_r - p["h_r"] * dphi) / p["sigma"],
        du, dy, dz,
    ]


def rhs_ramp(t, x, p, m, r):
    """The demo's drive without its controller: speed ramp, wheel imbalance and a pothole as
    yaw torques, and the coil current from a simple continuous state-feedback law
    I = min(i_max, gain * |mean wheel-yaw rate|) evaluated inside the right-hand side (no
    sampling, no sensors, no controller code, no estimator, no road noise)."""
    t_r = r["t_ramp_s"]
    tc = min(t, t_r)
    v = r["v0_mps"] + (r["v1_mps"] - r["v0_mps"]) * tc / t_r
    # Wheel angle: integral of v / R (ramp, then constant speed).
    dist = r["v0_mps"] * tc + 0.5 * (r["v1_mps"] - r["v0_mps"]) * tc * tc / t_r
    dist += max(t - t_r, 0.0) * r["v1_mps"]
    th = dist / p["r"]
    tq = [r["imbalance_nm"] * np.sin(th + ph) for ph in r["imbalance_phase_rad"]]
    tau = t - r["pothole_t_s"]
    if 0.0 <= tau < r["pothole_duration_s"]:
        bump = r["pothole_nm"] * np.sin(np.pi * tau / r["pothole_duration_s"])
        tq = [tq[0] + bump, tq[1] + bump]
    u_cmd = min(r["i_max_a"], r["gain_a_per_radps"] * abs(0.5 * (x[4] + x[5])))
    return rhs(t, x, p, m, v, u_cmd, tq)


def linear_a(p, v):
    """A(V) of the linearised plant without damper (tyres linear: F = C_a a)."""
    h = p["i_p"] * v / p["r"]
    ca, trail = p["c_a"], p["e"] + p["t_p"]
    m_inv = np.diag(1.0 / np.array([p["i_k"], p["i_k"], p["i_phi"], p["j_sw"]]))
    k = np.array([
        [p["k_tr"] + p["k_d"], -p["k_tr"], 0.0, -p["k_d"] / p["i_s"]],
        [-p["k_tr"], p["k_tr"], 0.0, 0.0],
        [0.0, 0.0, p["k_phi"], 0.0],
        [-p["k_d"] / p["i_s"], 0.0, 0.0, p["k_d"] / p["i_s"] ** 2],
    ])
    c = np.array([
        [p["c_k"], 0.0, h, 0.0],
        [0.0, p["c_k"], h, 0.0],
        [-h, -h, p["c_phi"], 0.0],
        [0.0, 0.0, 0.0, p["c_sw"]],
    ])
    g = np.array([[-trail * ca, 0.0], [0.0, -trail * ca], [p["h_r"] * ca, p["h_r"] * ca], [0.0, 0.0]])
    a = np.zeros((10, 10))
    a[0:4, 4:8] = np.eye(4)
    a[4:8, 0:4] = -m_inv @ k
    a[4:8, 4:8] = -m_inv @ c
    a[4:8, 8:10] = m_inv @ g
    s = p["sigma"]
    a[8, 0], a[9, 1] = v / s, v / s
    a[8, 4], a[9, 5] = p["e"] / s, p["e"] / s
    a[8, 6], a[9, 6] = -p["h_r"] / s, -p["h_r"] / s
    a[8, 8], a[9, 9] = -v / s, -v / s
    return a


G0 = 9.80665


def truck_operating_point(t):
    """Wheel load, cornering stiffness, strut stiffness and roll stiffness/damping of the truck
    (docs/mining-truck.md, "Loads" and "Hydro-pneumatic strut")."""
    f_z = 0.5 * (t["front_empty_kg"] + t["payload_front_share"] * t["payload_kg"]) * G0
    strut_load = f_z - 0.5 * t["m_axle"] * G0
    area, n = t["hps_area_m2"], t["hps_n"]
    p_static = strut_load / area
    if p_static <= t["hps_p0_pa"]:
        sys.exit("strut topped out")
    # p V^n = p0 V0^n
    v_static = t["hps_v0_m3"] * (t["hps_p0_pa"] / p_static) ** (1.0 / n)
    k_strut = n * p_static * area**2 / v_static
    half_b, half_s = t["track"] / 2.0, t["strut_spacing"] / 2.0
    k_phi = 2.0 * t["k_tz"] * half_b**2 + 2.0 * k_strut * half_s**2
    c_phi = 2.0 * t["c_strut"] * half_s**2
    return f_z, t["c_a_per_fz"] * f_z, k_phi, c_phi


def truck_linear_a(t, v):
    """A(V) of the truck without damper: q = [psi_L, psi_R, phi, theta_c, y], x = [q, q', a_L, a_R],
    M q'' + C q' + K q = G a and sigma a_i' = V (psi_i - a_i) + e psi_i' - h_r phi' - y'."""
    _, ca, k_phi, c_phi = truck_operating_point(t)
    h = t["i_p"] * v / t["r"]
    trail = t["e"] + t["t_p"]
    m = np.diag([t["i_k"], t["i_k"], t["i_phi"], t["j_c"], t["m_axle"]])
    k = np.array([
        [t["k_tr"] + t["k_d"], -t["k_tr"], 0.0, -t["k_d"], 0.0],
        [-t["k_tr"], t["k_tr"], 0.0, 0.0, 0.0],
        [0.0, 0.0, k_phi, 0.0, 0.0],
        [-t["k_d"], 0.0, 0.0, t["k_d"] + t["k_h"], 0.0],
        [0.0, 0.0, 0.0, 0.0, t["k_y"]],
    ])
    c = np.array([
        [t["c_k"], 0.0, h, 0.0, 0.0],
        [0.0, t["c_k"], h, 0.0, 0.0],
        [-h, -h, c_phi, 0.0, 0.0],
        [0.0, 0.0, 0.0, t["c_h"], 0.0],
        [0.0, 0.0, 0.0, 0.0, t["c_y"]],
    ])
    g = np.array([
        [-trail * ca, 0.0],
        [0.0, -trail * ca],
        [t["h_r"] * ca, t["h_r"] * ca],
        [0.0, 0.0],
        [ca, ca],
    ])
    m_inv = np.linalg.inv(m)
    a = np.zeros((12, 12))
    a[0:5, 5:10] = np.eye(5)
    a[5:10, 0:5] = -m_inv @ k
    a[5:10, 5:10] = -m_inv @ c
    a[5:10, 10:12] = m_inv @ g
    s = t["sigma"]
    for row, wheel in ((10, 0), (11, 1)):
        a[row, wheel] = v / s
        a[row, 5 + wheel] = t["e"] / s
        a[row, 7] = -t["h_r"] / s
        a[row, 9] = -1.0 / s
        a[row, row] = -v / s
    return a


def truck_main(case_path, out_path):
    with open(case_path, "rb") as f:
        cfg = tomllib.load(f)
    t = cfg["truck"]
    with open(out_path, "w") as out:
        for v in cfg["case"]["speeds_mps"]:
            for lam in np.linalg.eigvals(truck_linear_a(t, v)):
                out.write(f"{float(v)!r} {float(lam.real)!r} {float(lam.imag)!r}\n")


def trailer_linear_a(t, v, c_damper):
    """A(V) of the trailer: q = [y, psi], x = [q, q', alpha],
    M q'' + D q' + K q = G alpha with the CG's lateral position y - a psi, and
    sigma alpha' = V (psi - alpha) - (y' - l psi') (docs/trailer.md, "Equations")."""
    m, a, l = t["m"], t["a"], t["l"]
    f_z = m * G0 * a / l
    ca = t["c_a_per_fz"] * f_z
    mass = np.array([[m, -m * a], [-m * a, t["i_z"] + m * a**2]])
    damping = np.diag([t["c_y"], c_damper * t["l_d"] ** 2])
    stiffness = np.diag([t["k_y"], 0.0])
    g = np.array([ca, -l * ca])
    m_inv = np.linalg.inv(mass)
    x = np.zeros((5, 5))
    x[0:2, 2:4] = np.eye(2)
    x[2:4, 0:2] = -m_inv @ stiffness
    x[2:4, 2:4] = -m_inv @ damping
    x[2:4, 4] = m_inv @ g
    s = t["sigma"]
    x[4, 1] = v / s
    x[4, 2] = -1.0 / s
    x[4, 3] = l / s
    x[4, 4] = -v / s
    return x


def trailer_main(case_path, out_path):
    with open(case_path, "rb") as f:
        cfg = tomllib.load(f)
    t, c = cfg["trailer"], cfg["case"]["damper_nspm"]
    with open(out_path, "w") as out:
        for v in cfg["case"]["speeds_mps"]:
            for lam in np.linalg.eigvals(trailer_linear_a(t, v, c)):
                out.write(f"{float(v)!r} {float(lam.real)!r} {float(lam.imag)!r}\n")


def dual_linear_a(d, v):
    """A(V) of the dual-front-axle truck without damper (docs/dual-axle-truck.md):
    q = [psi_1L, psi_1R, psi_2L, psi_2R, phi_1, phi_2, theta_g, theta_m], x = [q, q', a_1L, a_1R,
    a_2L, a_2R]; the potential energy is a sum of springs 1/2 k (r_i q_i - r_j q_j)^2, K its
    Hessian; M q'' + C q' + K q = G a, sigma a' = V (psi - a) + e psi' - h_r phi_i'."""
    f_z = [0.5 * d["axle_load_1_kg"] * G0, 0.5 * d["axle_load_2_kg"] * G0]
    c_a = [d["c_a_per_fz"] * f for f in f_z]
    half_b, half_s = d["track"] / 2.0, d["spring_spacing"] / 2.0
    k_phi = 2.0 * d["k_tz"] * half_b**2 + 2.0 * d["k_spring"] * half_s**2
    c_phi = 2.0 * d["c_shock"] * half_s**2
    n_2 = (d["wheelbase"] - d["axle_spacing"]) / d["wheelbase"]
    h = d["i_p"] * v / d["r"]
    # the springs as (i, j, stiffness, r_i, r_j) and to ground (i, stiffness)
    springs = [(0, 1, d["k_tr"], 1.0, 1.0), (2, 3, d["k_tr"], 1.0, 1.0),
               (0, 6, d["k_d1"], 1.0, 1.0), (2, 7, d["k_d2"], 1.0, 1.0),
               (7, 6, d["k_t"], 1.0, n_2)]
    grounded = [(6, d["k_g"]), (4, k_phi), (5, k_phi)]
    k = np.zeros((8, 8))
    for i, j, s, ri, rj in springs:
        u = np.zeros(8)
        u[i], u[j] = ri, -rj
        k += s * np.outer(u, u)
    for i, s in grounded:
        k[i, i] += s
    m = np.diag([d["i_k"]] * 4 + [d["i_phi"]] * 2 + [d["j_g"], d["j_m"]])
    c = np.diag([d["c_k"]] * 4 + [c_phi] * 2 + [d["c_g"], d["c_m"]])
    wheels = [(0, 4, c_a[0]), (1, 4, c_a[0]), (2, 5, c_a[1]), (3, 5, c_a[1])]
    g = np.zeros((8, 4))
    for n, (w, ax, ca) in enumerate(wheels):
        c[w, ax] += h
        c[ax, w] -= h
        g[w, n] = -(d["e"] + d["t_p"]) * ca
        g[ax, n] = d["h_r"] * ca
    m_inv = np.linalg.inv(m)
    a = np.zeros((20, 20))
    a[0:8, 8:16] = np.eye(8)
    a[8:16, 0:8] = -m_inv @ k
    a[8:16, 8:16] = -m_inv @ c
    a[8:16, 16:20] = m_inv @ g
    s = d["sigma"]
    for n, (w, ax, _) in enumerate(wheels):
        row = 16 + n
        a[row, w] = v / s
        a[row, 8 + w] = d["e"] / s
        a[row, 8 + ax] = -d["h_r"] / s
        a[row, row] = -v / s
    return a


def eig_main(build, section, case_path, out_path):
    with open(case_path, "rb") as f:
        cfg = tomllib.load(f)
    with open(out_path, "w") as out:
        for v in cfg["case"]["speeds_mps"]:
            for lam in np.linalg.eigvals(build(cfg[section], v)):
                out.write(f"{float(v)!r} {float(lam.real)!r} {float(lam.imag)!r}\n")


def main():
    if sys.argv[1] == "truck":
        truck_main(sys.argv[2], sys.argv[3])
        return
    if sys.argv[1] == "trailer":
        trailer_main(sys.argv[2], sys.argv[3])
        return
    if sys.argv[1] == "dual":
        eig_main(dual_linear_a, "dual", sys.argv[2], sys.argv[3])
        return
    case_path, out_path = sys.argv[1], sys.argv[2]
    with open(case_path, "rb") as f:
        cfg = tomllib.load(f)
    p, m, c = cfg["plant"], cfg["damper"], cfg["case"]
    x0 = np.zeros(13)
    x0[0] = x0[1] = np.radians(c["initial_yaw_deg"])
    t_eval = np.array(c["sample_times_s"])
    atol = np.array(c["atol"])
    # Every method at the simulator's own tolerances; the fastest is the peer.
    methods = {}
    for method in c["methods"]:
        start = time.perf_counter()
        sol = solve_ivp(rhs, (0.0, c["duration_s"]), x0, method=method, t_eval=t_eval,
                        rtol=c["rtol"], atol=atol, args=(p, m, c["speed_mps"], c["current_a"]))
        wall = time.perf_counter() - start
        if not sol.success:
            sys.exit(f"solve_ivp ({method}) failed: {sol.message}")
        methods[method] = {"wall_s": wall, "rhs_evals": int(sol.nfev)}
    fastest = min(methods, key=lambda k: methods[k]["wall_s"])
    # The trajectory the Rust one is checked against: tighter than the simulator (untimed), so
    # the difference is the simulator's own error.
    sol = solve_ivp(rhs, (0.0, c["duration_s"]), x0, method="LSODA", t_eval=t_eval,
                    rtol=1e-10, atol=1e-13, args=(p, m, c["speed_mps"], c["current_a"]))
    if not sol.success:
        sys.exit(f"solve_ivp (accuracy run) failed: {sol.message}")
    speeds = np.array(c["sweep_speeds_mps"])
    start = time.perf_counter()
    stack = np.stack([linear_a(p, v) for v in speeds])
    build_wall = time.perf_counter() - start
    start = time.perf_counter()
    max_re = np.linalg.eigvals(stack).real.max(axis=1).tolist()  # one batched LAPACK call
    eig_wall = time.perf_counter() - start
    ramp = {}
    if "ramp" in cfg:
        r = cfg["ramp"]
        # Three pieces so that the integrator cannot step over the 20 ms pothole.
        t_p, d_p = r["pothole_t_s"], r["pothole_duration_s"]
        edges = [0.0, t_p, t_p + d_p, r["duration_s"]]
        x, nfev, peak = np.zeros(13), 0, 0.0
        start = time.perf_counter()
        for t0, t1 in zip(edges[:-1], edges[1:]):
            sol_r = solve_ivp(rhs_ramp, (t0, t1), x, method=fastest, rtol=c["rtol"],
                              atol=atol, args=(r["plant"], m, r))
            if not sol_r.success:
                sys.exit(f"solve_ivp (ramp) failed: {sol_r.message}")
            x, nfev = sol_r.y[:, -1], nfev + int(sol_r.nfev)
            peak = max(peak, float(np.max(np.abs(sol_r.y[0]))))
        ramp_wall = time.perf_counter() - start
        ramp = {
            "ramp_wall_s": ramp_wall,
            "ramp_rhs_evals": nfev,
            "ramp_peak_psi_l_rad": peak,
        }
    json.dump({
        **ramp,
        "methods": methods,
        "fastest": fastest,
        "sim_wall_s": methods[fastest]["wall_s"],
        "psi_l_rad": sol.y[0].tolist(),
        "sweep_build_wall_s": build_wall,
        "sweep_eig_wall_s": eig_wall,
        "max_re": max_re,
    }, open(out_path, "w"))


if __name__ == "__main__":
    main()
