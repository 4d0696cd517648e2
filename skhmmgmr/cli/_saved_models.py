"""The report's saved models: portable JSON, C source and FMU of every model meant to leave.

Each file goes into the report's folder beside the tables, with an entry that says what it is
and the two lines that load it (:func:`save_models`). The FMU needs FMPy's FMI headers and the
system C compiler: without them it is skipped, and the report says why in one line.
"""

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

#: How each kind of file is loaded: two lines, ``{file}`` and ``{key}`` filled in.
LOADERS = {
    "portable JSON": (
        "from skhmmgmr import portable\n"
        'model = portable.load("{file}")  # then model.predict(X) with the inputs below'
    ),
    "C source": (
        'cc -std=c99 -O2 -c {key}.c   # and in your code: #include "{key}.h"\n'
        "{key}_reset(&state); {key}_update(&state, inputs, &torque, &std);  /* per sample */"
    ),
    "FMU": (
        "import fmpy\n"
        'result = fmpy.simulate_fmu("{file}", input=signals, output_interval={period!r})'
    ),
}


def _entry(candidate, file, kind, what, period):
    code = LOADERS[kind].format(file=file, key=candidate.key, period=float(f"{period:.6g}"))
    return {
        "name": f"{candidate.key} ({kind})",
        "file": file,
        "caption": what,
        "code": code,
        "kind": kind,
        "model": candidate.key,
        "label": candidate.label,
        "inputs": list(candidate.features),
    }


def _fmu_unavailable():
    """Why no FMU can be built here (None when it can)."""
    import shutil

    try:
        import fmpy  # noqa: F401
    except ImportError:
        return "FMPy is not installed (pip install 'skhmmgmr[fmu]')"
    if shutil.which("cc") is None:
        return "there is no C compiler 'cc' on the PATH"
    return None


def save_models(candidates, folder, *, sampling_period, notes):
    """Write every model of ``candidates`` marked ``saved`` into ``folder``: its entries.

    ``notes`` (a list) receives one line per kind of file skipped, and why.
    """
    from .. import portable
    from ..export import write_c, write_fmu

    folder = Path(folder)
    saved = [candidate for candidate in candidates if candidate.saved]
    no_fmu = _fmu_unavailable()
    if no_fmu is not None:
        notes.append(f"The FMUs are not written: {no_fmu}.")
    by_model = {}
    for candidate in saved:
        entries = by_model[candidate.key] = []
        file = f"{candidate.key}.json"
        portable.save(candidate.model, folder / file, sampling_period=sampling_period)
        what = "portable model file (JSON, read by any language; predict bit for bit)"
        entries.append(_entry(candidate, file, "portable JSON", what, sampling_period))
        header, source = write_c(candidate.model, folder, name=candidate.key)
        what = "C99 source of its causal filter, one sample per call (header beside it)"
        entries.append(_entry(candidate, source.name, "C source", what, sampling_period))
        header_entry = {"name": f"{candidate.key} (C header)", "file": header.name, "code": ""}
        entries.append({**entries[-1], **header_entry, "caption": f"Header of {source.name}."})
    if no_fmu is None:

        def fmu(candidate):
            path = write_fmu(
                candidate.model, folder / f"{candidate.key}.fmu", sampling_period=sampling_period
            )
            what = "co-simulation FMU (FMI 2.0) for vehicle simulators, binary for this platform"
            by_model[candidate.key].append(
                _entry(candidate, path.name, "FMU", what, sampling_period)
            )

        # the C compiler runs in a process of its own: two builds at a time on two cores
        with ThreadPoolExecutor(max_workers=2) as pool:
            list(pool.map(fmu, saved))
    return [entry for entries in by_model.values() for entry in entries]
