"""A small Monte Carlo campaign: how often does learning help when the true plants differ from
their models?

``python examples/run_a_campaign.py [SAMPLES] [OUT_FOLDER]`` (default 4 samples into
``my_campaign/``): true plants drawn from the built-in fleet's identified uncertainty, flown
through scenario 1 (first 10 s) with the closed-form and norm-optimal designs on a local Dask
cluster of one worker (hence the ``__main__`` guard: its worker processes import this
file). Run it again with more samples on the same folder: it resumes.
"""

import sys
from pathlib import Path

from ilcdob.app.commands import campaign_to_folder
from ilcdob.validation.campaign import CampaignOptions


def main() -> None:
    samples = int(sys.argv[1]) if len(sys.argv) > 1 else 4
    out = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("my_campaign")

    options = CampaignOptions(samples=samples, scenarios=(1,), methods=("closed-form", "norm-optimal"), duration=10.0)
    result = campaign_to_folder(out, options, workers=1,
                                progress=lambda done, total, what: print(f"\r{done}/{total} {what}", end="", flush=True))
    print()
    print(result)
    print(result.table(), end="")


if __name__ == "__main__":  # Dask starts worker processes that import this file
    main()
