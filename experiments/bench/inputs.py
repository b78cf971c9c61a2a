"""The reference inputs the benchmarks read: the PNNL and ACTIVSg cases beside the repository
(`SHARED`, read in place) and DYR data without the machine records their model rejects."""
from __future__ import annotations

import dataclasses
from pathlib import Path

from jaxgrid.io.dyr import read_dyr
from jaxgrid.models.base import ModelError
from jaxgrid.models.machines import MACHINES
from jaxgrid.records import DyrData

SHARED = Path(__file__).resolve().parents[3] / "shared" / "cases"


def without_bad_machines(path: Path) -> tuple[DyrData, list[str]]:
    """The DYR data without machine records their model rejects, and the reasons.

    ACTIVSg2000's cmld file has GENSAL records with Xl = X''d, which the machine models
    reject (spec machines-exciters-governors.md: Xl < X''d); in lenient mode their
    generators become constant-admittance negative loads.
    """
    data, kept, dropped = read_dyr(path), [], []
    for r in data.records:
        try:
            if r.model in MACHINES:
                MACHINES[r.model].read([r])
            kept.append(r)
        except ModelError as error:
            dropped.append(str(error))
    return dataclasses.replace(data, records=tuple(kept)), dropped
