"""Campaigns: sweep and Monte-Carlo studies of a scenario on Dask (``obsfmu sweep``).

A campaign runs one scenario over many values of some of its FMUs'
parameters -- grids, lists or random draws -- and records one row per
sample: its inputs, the run's status and reason, its wall time and the
scenario's summary metrics (convergence time, final error, converged or
not).  Samples run on a ``dask.distributed`` LocalCluster of worker
processes (or an existing cluster); each worker keeps its FMUs instantiated
across samples.  Rows go to a Parquet dataset as they finish, so an
interrupted campaign resumes where it stopped.  See ``docs/campaigns.md``.

Example::

    from obsfmu.fmus.campaign import Campaign, run_campaign

    study = Campaign("ltv-ls-bounded", vary={"plant.k[1]": "uniform(-4, -2)", "plant.x0[1]": "normal(2, 0.5)"},
                     samples=32, seed=1, stop_time=30.0)
    table = run_campaign(study, workers=2, out="results/ltv-k1")   # a pyarrow.Table, one row per sample

Modules: :mod:`.spec` (the SPEC grammar), :mod:`.design` (campaign, samples,
checks against the modelDescription), :mod:`.measures` (what a sample
measures), :mod:`.worker` (one sample on a reused Session), :mod:`.store`
(the Parquet dataset), :mod:`.runner` (Dask), :mod:`.table`, :mod:`.plots`,
:mod:`.progress`, :mod:`.cli` (``obsfmu sweep``).
"""

from __future__ import annotations

__all__ = ["Campaign", "Plan", "Sample", "run_campaign", "load_rows", "summary_text", "write_plots",
           "CampaignError", "parse_spec", "Measure"]


def __getattr__(name: str):
    """Import on first use: ``obsfmu --help`` must not pay for dask and pyarrow."""
    if name in ("Campaign", "Plan", "Sample"):
        from . import design as module
    elif name == "run_campaign":
        from . import runner as module
    elif name == "load_rows":
        from . import store as module
    elif name == "summary_text":
        from . import table as module
    elif name == "write_plots":
        from . import plots as module
    elif name == "CampaignError":
        from . import errors as module
    elif name == "parse_spec":
        from . import spec as module
    elif name == "Measure":
        from . import measures as module
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(module, name)
