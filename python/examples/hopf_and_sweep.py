# %% [markdown]
# # shimmy from Python: the Hopf window, an eigenvalue sweep, a closed-loop run
# Run as a script (`python python/examples/hopf_and_sweep.py`) or cell by cell in Jupyter /
# VS Code (`# %%` cells). Needs `pip install ./python` once; matplotlib only for the plot.

# %%
import numpy as np

import shimmy_sim

nominal = shimmy_sim.Vehicle("nominal")            # or a car file: shimmy_sim.Vehicle("my-car.toml")
worn = nominal.with_fields({"plant.c_a": 72000.0, "plant.sigma": 0.36})
for name, v in [("nominal", nominal), ("worn tyres", worn)]:
    window = shimmy_sim.hopf_window(v)
    print(f"{name:>10}: " + ", ".join(
        f"{c['kind']} {c['speed_kmh']:.2f} km/h ({c['freq_hz']:.2f} Hz)" for c in window))

# %% The MR damper at 0.5 A as its equivalent viscous damper closes the window.
print("with 0.5 A:", shimmy_sim.hopf_window(nominal, damper_current_a=0.5) or "no crossing")

# %% Growth rate of the critical mode over speed x steering-column stiffness.
speeds = np.arange(10.0, 151.0, 1.0)
k_d = np.linspace(5000.0, 15000.0, 11)
growth = np.array([
    shimmy_sim.eigen_sweep(nominal.with_fields({"plant.k_d": k}), speeds)["critical_re"]
    for k in k_d
])
unstable = (growth > 0).sum(axis=1)
for k, n in zip(k_d, unstable):
    print(f"k_d = {k:7.0f} N m/rad: unstable at {n:3d} of {len(speeds)} speeds (10..150 km/h)")

# %% One closed-loop run: a 0.5 deg kick at 55 km/h, ASMC vs no damper.
KICK = """duration_s = 4.0
[controller]
kind = "{kind}"
[speed]
constant_kmh = 55.0
[initial]
yaw_deg = 0.5
"""
runs = {kind: shimmy_sim.run_scenario_toml(KICK.format(kind=kind)) for kind in ("no-damper", "asmc")}
for kind, r in runs.items():
    m = r["metrics"]
    print(f"{kind:>9}: peak {np.degrees(m['peak_yaw_rad']):.3f} deg, "
          f"end amplitude {np.degrees(m['amp_end_rad']):.4f} deg, "
          f"rms current {m['rms_current_a']:.3f} A")

# %%
try:
    import matplotlib.pyplot as plt
except ImportError:
    plt = None
if plt is not None:
    fig, ax = plt.subplots()
    for kind, r in runs.items():
        ax.plot(r["trace"]["t_s"], np.degrees(r["trace"]["psi_l_rad"]), label=kind)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("left wheel yaw [deg]")
    ax.legend()
    fig.savefig("kick.png", dpi=120)
    print("wrote kick.png")
