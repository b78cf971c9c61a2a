"""Decision latency: the time a controller takes to turn one observation into one action.

    python -m experiments.bench.latency [--studies ieee39_fidvr ieee300_fidvr]
        [--batch 1024] [--calls 200] [--mpc "horizon=1,iterations=10"] [--mpc-batch 32]
        [--out benchmarks/cpu/latency.json]

For each study, the PARS policies (each kind on the observations the study stacks for it,
`Study.history`; widths of the paper's preset for the grid's size,
`experiments.common.training.paper_preset`) with their observation normaliser, or given
trained policies (`controller_latency.bench_study(..., policies=)`, as
`experiments.reproduce`'s tab3), the UVLS relays and the MPC (`baselines.mpc`, options
--mpc): the median wall time of one jitted decision for one task (batch 1, result on the
host), and the time per decision when a batch of tasks decides at once (one vmapped call /
batch; --mpc-batch for the MPC). The MPC decides from the state 0.3 s after the start of the
study's first test fault, the policies from a constant observation. The paper's Table III
reports 0.72 s per PARS decision and 63.31 s per MPC decision. Compile time is excluded; θ
is random unless trained policies are given (the cost does not depend on its values).
"""
from __future__ import annotations

import argparse

from experiments.bench.controller_latency import bench_study
from experiments.bench.timing import write_report


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--studies", nargs="*", default=["ieee39_fidvr", "ieee300_fidvr"],
                        help="built-in study names or study files")
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--mpc", default="", help="MPC options (baselines.mpc), e.g. horizon=1")
    parser.add_argument("--mpc-batch", type=int, default=32)
    parser.add_argument("--out", default="benchmarks/cpu/latency.json")
    args = parser.parse_args(argv)
    write_report(args.out, paper_s={"pars": 0.72, "mpc": 63.31},
                 studies=[bench_study(s, args.batch, args.calls, args.mpc, args.mpc_batch)
                          for s in args.studies])


if __name__ == "__main__":
    main()
