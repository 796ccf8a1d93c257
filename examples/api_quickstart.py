"""The Python API in one run: simulate the paper's sec. 4.2 roof, fit it, read the result.

    python examples/api_quickstart.py      # from the repository root; ~12 s

The same code as the README's "Python API" section; the same steps as `vibinverse simulate` ->
`vibinverse fit --method map`. The result file goes to a fresh temporary directory.
"""

# ruff: noqa: T201  (an example prints its results)

import tempfile
from pathlib import Path

import vibinverse as vi

scene = vi.load_scene("examples/scenes/roof_frame.toml", overrides=["noise.sigma=0.6"])  # validated table
obs = vi.simulate(scene, seed=3)  # time, intensity, intensity_clean, sensitivity
series = vi.series(obs.time, obs.intensity, scene=scene)  # scene: the summary reports the true values
# measured data instead: series = vi.load_series("frame.csv")  (CSV/TSV, Parquet, .npy, .npz or netCDF;
#   a table's columns: time_column=, value_column=, or fs= for values only; series.notes: time reference, units)

result = vi.fit(series, scene, method="map")  # MAP + Laplace; "casadi": exact derivatives; "auto": + emcee
for name, p in result.summary()["parameters"].items():  # the JSON the CLI writes
    print(f"{name:<42} {p['map']:<11.5g} 90% [{p['q05']:.5g}, {p['q95']:.5g}]  truth {p['truth']:.5g}")
for d in result.detections:  # the same as vi.detect(result)
    print(f"{d.what}: log-likelihood gain {d.delta_loglike:.1f}, threshold {d.threshold:.1f}, detected {d.detected}")
with tempfile.TemporaryDirectory(prefix="vibinverse-") as tmp:  # your own path in a real run
    path = result.to_netcdf(Path(tmp) / "result.nc")
    summary, idata = vi.read_result(path)  # the summary and ArviZ InferenceData
    print(f"wrote and read back {path.name}; groups: {', '.join(idata.groups())}")
