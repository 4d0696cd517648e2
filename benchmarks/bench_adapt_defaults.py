"""Which defaults of ``HMMGMRRegressor.adapt`` the evidence supports (#37).

Protocol (simulator, measured sensors, 20 Hz, the five features of ``bench_ahead.py``, K=5),
in every car asked for (``--vehicles``: ``default`` is the reference car, an int the car
``draw_vehicle`` draws from it) and for every driver style held out in turn:

- a generic model is fitted on the two other styles (``--generic-minutes`` one-minute training
  sections each, settings 1-6 in turn);
- the held-out style drives 5 one-minute adaptation sections (settings 1-5), two 2-minute
  validation sections and three 2-minute test sections (setting 7, roads of their own);
- the generic model is adapted to its first 1, 2 and 5 minutes with every pair of
  ``parameters`` ("m", "mv", "mt", "mvt") and relevance (4, 16, 64, 256, 1024), and a model
  of the same K is fitted from scratch on the same minutes.

The pair with the best mean validation accuracy over every seed, car, style and number of
minutes (ties to 0.05 point: the fewer adapted parameters, then the smoother) is the chosen
default; the tables report its test accuracy
(mean over the held-out styles and cars) against the old defaults ("m", 16), the generic model
and the from-scratch model, per number of minutes, in the reference car and in the drawn cars.

``--timing`` also times one ``FilterStream.update`` (K=5, 5 inputs): plain, with online
adaptation of the means (``relevance=16``, a target every sample), and a prototype of online
adaptation of the regression slopes (the cross-covariance of every state's inputs and output
adapted by the same MAP rule, the input covariances kept, so that the slopes are
``S_FF^-1 S_FT`` with ``S_FF^-1`` fixed; slopes and intercepts rewritten in the stream's
weights after every learned sample), each against the plain update. Run with::

    nice python benchmarks/bench_adapt_defaults.py --vehicles default 0 1 --timing
    nice python benchmarks/bench_adapt_defaults.py --quick   # one car, 4 generic minutes
"""

import argparse
import copy
import time
import warnings

import numpy as np
import pandas as pd

# the same features, rate, arrays and scores as the adaptation benchmark
from bench_adaptation import arrays, scores
from bench_ahead import FEATURES
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_lane_keeping

RATE = 20.0
STYLES = ("defensive", "aggressive", "novice")
PARAMETERS = ("m", "mv", "mt", "mvt")
RELEVANCES = (4.0, 16.0, 64.0, 256.0, 1024.0)
MINUTES = (1, 2, 5)
OLD_DEFAULTS = ("m", 16.0)
N_STATES = 5


def recordings(style, sections, seed, vehicle):
    """Frames of ``sections`` (split, setting, duration) driven by ``style`` in ``vehicle``."""
    rng = np.random.default_rng(seed)
    frames = []
    for i, (split, setting, duration) in enumerate(sections):
        frame = make_lane_keeping(
            duration,
            setting=setting,
            driver=style,
            sampling_rate=RATE,
            random_state=int(rng.integers(2**31 - 1)),
            recording=f"{style}-{split}-{i:02d}",
            split=split,
            vehicle=vehicle,
        )
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def car(vehicle, generic_minutes, seed):
    """Per held-out style: rows of (setting, minutes, split, accuracy, roughness)."""
    data = {}
    for s, style in enumerate(STYLES):
        sections = [("train", 1 + i % 6, 60.0) for i in range(generic_minutes)]
        sections += [("adapt", 1 + i, 60.0) for i in range(max(MINUTES))]
        sections += [("validation", 7, 120.0)] * 2 + [("test", 7, 120.0)] * 3
        data[style] = recordings(style, sections, seed * 10 + s, vehicle)
    rows = []
    for held_out in STYLES:
        train = pd.concat([data[s] for s in STYLES if s != held_out])
        train = train[train["split"] == "train"]
        generic = HMMGMRRegressor(n_states=N_STATES, random_state=0).fit(*arrays(train))
        frame = data[held_out]
        splits = {split: arrays(frame[frame["split"] == split]) for split in ("validation", "test")}
        adapt = frame[frame["split"] == "adapt"]
        names = list(dict.fromkeys(adapt["recording"]))

        def record(setting, minutes, model, base=(held_out,), splits=splits):
            for split, split_data in splits.items():
                rows.append((*base, setting, minutes, split, *scores(model, split_data)))

        record("generic", 0, generic)
        for minutes in MINUTES:
            few = arrays(adapt[adapt["recording"].isin(names[:minutes])])
            scratch = HMMGMRRegressor(n_states=N_STATES, random_state=0).fit(*few)
            record("scratch", minutes, scratch)
            for parameters in PARAMETERS:
                for relevance in RELEVANCES:
                    model = copy.deepcopy(generic)
                    try:
                        model.adapt(*few, parameters=parameters, relevance=relevance)
                    except ValueError:  # a covariance not positive definite
                        continue
                    record(f"{parameters} r={relevance:g}", minutes, model)
    return rows


def report(table):
    table["cars"] = np.where(table["vehicle"] == "default", "reference car", "drawn cars")
    validation = table[table["split"] == "validation"]
    adapted = validation[~validation["setting"].isin(["generic", "scratch"])]
    by_setting = adapted.groupby("setting")[["accuracy", "roughness"]].mean()
    grid = (
        adapted.pivot_table(index="setting", columns="minutes", values="accuracy")
        .join(by_setting)
        .sort_values("accuracy", ascending=False)
    )
    print("\nvalidation accuracy % (mean over cars and held-out styles) per minutes, and overall")
    print(grid.to_string(float_format=lambda v: f"{v:.2f}"))
    top = by_setting["accuracy"].max()
    near = by_setting[by_setting["accuracy"] >= top - 0.05]
    chosen = min(near.index, key=lambda s: (len(s.split()[0]), near.loc[s, "roughness"]))
    old = f"{OLD_DEFAULTS[0]} r={OLD_DEFAULTS[1]:g}"
    print(f"\nchosen on validation: {chosen} (old defaults: {old})")
    test = table[table["split"] == "test"]
    for cars, rows in [("all cars", test), *test.groupby("cars")]:
        lines = []
        for minutes in MINUTES:
            at = rows[rows["minutes"] == minutes].groupby("setting")["accuracy"].mean()
            generic = rows[rows["setting"] == "generic"]["accuracy"].mean()
            lines.append(
                {
                    "minutes": minutes,
                    "generic": generic,
                    "scratch": at["scratch"],
                    f"old {old}": at[old],
                    f"new {chosen}": at[chosen],
                    "best on test": at.drop("scratch").max(),
                    "best setting": at.drop("scratch").idxmax(),
                }
            )
        print(f"\ntest accuracy %, {cars} (mean over the held-out styles)")
        print(pd.DataFrame(lines).to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    per_style = test[test["setting"].isin([old, chosen, "generic", "scratch"])]
    print("\ntest accuracy % per car and held-out style at 2 minutes (mean over the seeds)")
    two = per_style[(per_style["minutes"] == 2) | (per_style["setting"] == "generic")]
    print(
        two.pivot_table(index=["vehicle", "style"], columns="setting", values="accuracy").to_string(
            float_format=lambda v: f"{v:.2f}"
        )
    )
    return chosen


def slope_prototype(stream, model, relevance):
    """``learn(target)``: online MAP adaptation of every state's input-output cross-covariance
    (slopes ``S_FF^-1 S_FT``, ``S_FF`` fixed), rewriting the stream's slopes and intercepts."""
    emissions, n_inputs = model.emissions, model.n_inputs
    covariances = emissions.state_covariances()
    precision = np.linalg.inv(covariances[:, :n_inputs, :n_inputs])  # (K, D, D)
    prior_cross = covariances[:, :n_inputs, n_inputs]  # (K, D)
    input_means, output_means = emissions.means[:, :n_inputs], emissions.means[:, n_inputs]
    weights = stream._weights
    n_terms = weights.shape[1] - model.n_states
    counts = np.zeros(model.n_states)
    cross = np.zeros_like(prior_cross)
    center, scale = stream._center_0, stream._scale_0

    def learn(target):
        nonlocal counts, cross
        alpha, z = stream._alpha, stream._z_inputs
        output = (target - center) / scale
        counts += alpha
        cross += (alpha * (output - output_means))[:, np.newaxis] * (z - input_means)
        adapted = (cross + relevance * prior_cross) / (counts + relevance)[:, np.newaxis]
        slopes = np.einsum("kij,kj->ki", precision, adapted)
        weights[:n_inputs, n_terms:] = slopes.T
        weights[n_inputs, n_terms:] = output_means - np.einsum("ki,ki->k", slopes, input_means)

    return learn


def timing(n_calls=20000):
    """Median microseconds per update: plain, means adaptation, means + slopes prototype."""
    frame = make_lane_keeping(300.0, sampling_rate=RATE, random_state=0)
    X, y = frame[FEATURES].to_numpy(), frame["driver_torque"].to_numpy()
    model = HMMGMRRegressor(n_states=N_STATES, random_state=0).fit(X, y)
    fitted = model.model_

    def run(update):
        elapsed = np.empty(n_calls)
        for i in range(n_calls):
            row, target = X[i % len(X)], float(y[i % len(y)])
            start = time.perf_counter_ns()
            update(row, target)
            elapsed[i] = time.perf_counter_ns() - start
        return float(np.median(elapsed[1000:])) / 1000.0

    plain = model.filter_stream()
    means = model.filter_stream(relevance=16.0)
    both = model.filter_stream(relevance=16.0)
    slopes_only = model.filter_stream()
    learn_both = slope_prototype(both, fitted, 16.0)
    learn_slopes = slope_prototype(slopes_only, fitted, 16.0)

    def update_both(row, target):
        both.update(row, target=target)
        learn_both(target)

    def update_slopes(row, target):
        slopes_only.update(row)
        learn_slopes(target)

    cases = {
        "plain update": lambda row, target: plain.update(row),
        "means (relevance=16)": lambda row, target: means.update(row, target=target),
        "slopes prototype": update_slopes,
        "means + slopes prototype": update_both,
    }
    results = {name: [] for name in cases}
    for _ in range(3):  # interleaved repeats, the fastest of each
        for name, update in cases.items():
            results[name].append(run(update))
    base = min(results["plain update"])
    print("\nFilterStream.update, K=5, 5 inputs, median us (fastest of 3 runs)")
    for name, values in results.items():
        print(f"  {name:<26} {min(values):6.2f} us  {min(values) / base:4.2f}x plain")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", nargs="+", default=["default", "0", "1"])
    parser.add_argument("--generic-minutes", type=int, default=12)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--timing", action="store_true", help="also time online slopes")
    parser.add_argument("--output", default=None, help="CSV of every figure")
    args = parser.parse_args()
    vehicles, generic_minutes = args.vehicles, args.generic_minutes
    if args.quick:
        vehicles, generic_minutes = vehicles[:1], 4
    warnings.filterwarnings("ignore", category=ConvergenceWarning)
    tables = []
    with threadpool_limits(1):
        for seed in args.seeds:
            for vehicle in vehicles:
                start = time.perf_counter()
                spec = None if vehicle == "default" else int(vehicle)
                rows = car(spec, generic_minutes, seed)
                columns = ["style", "setting", "minutes", "split", "accuracy", "roughness"]
                frame = pd.DataFrame(rows, columns=columns)
                tables.append(frame.assign(vehicle=vehicle, seed=seed))
                print(f"seed {seed}, car {vehicle}: {time.perf_counter() - start:.0f} s")
        table = pd.concat(tables, ignore_index=True)
        if args.output:
            table.to_csv(args.output, index=False)
        report(table)
        if args.timing:
            timing()


if __name__ == "__main__":
    main()
