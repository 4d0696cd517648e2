"""The command line on a dask cluster: the ``--scheduler`` option of ``demo`` and ``select``.

``--scheduler local:N`` starts a local cluster of N worker processes for the run; an address
(``tcp://host:8786``) connects to a running scheduler (a SLURM or Kubernetes cluster, see the
user guide's "Running on a cluster"). The framework's evaluations then run as dask tasks
through :func:`skhmmgmr.cluster.use_cluster`; without the option they run on this machine
through joblib (``--n-jobs``).
"""

from contextlib import nullcontext

from ._files import CommandError


def add_scheduler_option(parser):
    text = (
        "dask scheduler to run the fits on: 'local:N' (N worker processes on this machine) or "
        "an address such as tcp://host:8786 (default: joblib on this machine, --n-jobs)"
    )
    parser.add_argument("--scheduler", default=None, help=text)


def scheduler_context(args):
    """The block the framework runs in: on the scheduler of ``--scheduler``, if any."""
    if not getattr(args, "scheduler", None):
        return nullcontext()
    try:
        import distributed  # noqa: F401
    except ImportError as exc:
        raise CommandError(
            "--scheduler needs dask's distributed scheduler: pip install 'dask[distributed]'"
        ) from exc
    from ..cluster import use_cluster

    return use_cluster(args.scheduler)
