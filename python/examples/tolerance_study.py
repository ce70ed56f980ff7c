"""Tolerance study on Dask: the shimmy onset speed of a production spread of cars.

Each sample is the nominal car with its tyre, damper-free steering and geometry parameters drawn
from their manufacturing and wear tolerances (uniform, seeded); each task computes that car's
Hopf window. The study prints the onset's spread and the share of cars whose shimmy starts
below a design speed.

    python python/examples/tolerance_study.py                      # Dask's local cluster
    python python/examples/tolerance_study.py --scheduler tcp://host:8786   # a cluster

The workers need only `pip install ./python` (and dask[distributed]). Every call releases the
GIL, so a local cluster of threads (`--threads`) is as fast as one of processes on one machine.
"""
import argparse

import numpy as np
from dask.distributed import Client, LocalCluster

import shimmy_sim

# Field, relative tolerance (+-): tyre cornering stiffness and relaxation length (wear,
# inflation), steering stiffness (joints), pneumatic trail.
TOLERANCES = {"plant.c_a": 0.15, "plant.sigma": 0.15, "plant.k_d": 0.10, "plant.t_p": 0.10}


def samples(n, seed):
    """`n` field dicts drawn uniformly within the tolerances around the nominal car."""
    nominal = shimmy_sim.Vehicle("nominal")
    rng = np.random.default_rng(seed)
    return [
        {f: nominal.get(f) * (1.0 + tol * rng.uniform(-1.0, 1.0)) for f, tol in TOLERANCES.items()}
        for _ in range(n)
    ]


def onset_kmh(fields):
    """The first Hopf onset of the car with `fields`, km/h (inf: none up to 150 km/h)."""
    window = shimmy_sim.hopf_window(shimmy_sim.Vehicle("nominal").with_fields(fields))
    onsets = [c["speed_kmh"] for c in window if c["kind"] == "onset"]
    return min(onsets, default=float("inf"))


def study(client, n, seed):
    """The onset speeds of `n` sampled cars, computed on `client`'s workers, in sample order."""
    futures = client.map(onset_kmh, samples(n, seed), pure=False)
    return np.array(client.gather(futures))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=400)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--design-speed-kmh", type=float, default=25.0)
    ap.add_argument("--scheduler", help="address of a Dask scheduler (default: a local cluster)")
    ap.add_argument("--threads", action="store_true", help="local cluster of threads, not processes")
    a = ap.parse_args(argv)
    if a.samples < 1:
        ap.error("--samples must be at least 1")
    if a.scheduler:
        client = Client(a.scheduler)
    else:
        client = Client(LocalCluster(processes=not a.threads, dashboard_address=None))
    with client:
        onsets = study(client, a.samples, a.seed)
    finite = onsets[np.isfinite(onsets)]
    print(f"{a.samples} cars, tolerances " + ", ".join(f"{f} +-{t:.0%}" for f, t in TOLERANCES.items()))
    if finite.size:
        lo, p5, med = np.min(finite), np.percentile(finite, 5), np.median(finite)
        print(f"shimmy onset: min {lo:.2f} km/h, 5th percentile {p5:.2f} km/h, median {med:.2f} km/h")
    print(f"no onset up to 150 km/h: {np.sum(~np.isfinite(onsets))} cars")
    below = np.mean(onsets < a.design_speed_kmh)
    print(f"onset below {a.design_speed_kmh:.1f} km/h: {below:.1%} of cars")
    return onsets


if __name__ == "__main__":
    main()
