"""``hexactl demo``: the paper's experiment end to end on the simulator (:mod:`hexactl.application.demo`).

Exit status: 0 the calibration improved the accuracy, 1 it did not (or the campaign could
not finish), 2 bad input (the results directory holds a finished demo: ``--force``),
130 interrupted (run again to resume).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hexactl.adapters.cli.common import (CliError, campaign_stopped, check_campaign_arguments, check_writable,
                                        named_path, non_negative_int, whole_number)
from hexactl.adapters.cli.dashboard_commands import DEFAULT_HTTP, checked_http

DEFAULT_OUT = Path("demo-out")


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    demo = subparsers.add_parser(
        "demo",
        parents=[common],
        help="the paper's experiment end to end on the simulator: measure, calibrate, hot-load, measure again",
        declare=_declare_demo,
        description="Start the controller service on the simulator (control loop, in-process CAN bus, six simulated "
        "actuator firmwares, a platform with seeded manufacturing errors, simulated theodolites), measure the "
        "paper's test motions, run the leg-lock campaign for all six legs through the API, identify the "
        "parameters, hot-load the calibration into the running controller, measure the motions again, and print "
        "the paper's Table 1 and the largest errors as a percentage of the stroke. Writes the calibration, the "
        "data and the report (HTML and PNG) into DIR. Exit status 1 if the calibration did not improve the "
        "accuracy.",
        epilog="An interrupted demo resumes when run again with the same DIR and options. See docs/calibration.md.",
    )
    demo.set_defaults(run=run_demo_command)


def _declare_demo(demo: argparse.ArgumentParser) -> None:
    from hexactl.application.demo import DEMO_ENVELOPE_FRACTION, DEMO_FAULTS_IN_A_ROW, DEMO_POSTURES_PER_LEG

    demo.add_argument("--out", type=named_path, default=DEFAULT_OUT, metavar="DIR",
                      help=f"results directory (default ./{DEFAULT_OUT})")
    demo.add_argument("--seed", type=non_negative_int, default=0,
                      help="seed of the manufacturing errors, the instrument noise and the plan (default 0)")
    demo.add_argument("--per-leg", type=whole_number, default=DEMO_POSTURES_PER_LEG, metavar="N",
                      help=f"leg-lock postures per leg (default {DEMO_POSTURES_PER_LEG}, to finish in under two minutes; "
                      "the paper measured 20)")
    demo.add_argument("--envelope", type=float, default=DEMO_ENVELOPE_FRACTION, metavar="F",
                      help=f"plan within this fraction of the pose envelope (default {DEMO_ENVELOPE_FRACTION:g}: shorter "
                      "moves)")
    demo.add_argument("--force", action="store_true", help="replace the results of a finished demo in DIR")
    demo.add_argument("--dashboard", nargs="?", const=DEFAULT_HTTP, metavar="HOST:PORT",
                      help=f"watch it in the browser dashboard, served there (default {DEFAULT_HTTP}) while the demo runs")
    demo.add_argument("--reset-faults", type=non_negative_int, default=DEMO_FAULTS_IN_A_ROW, metavar="N",
                      help="reset a latched fault and go on, unless it is the N+1-th in a row with no measurement saved "
                      f"between them (default {DEMO_FAULTS_IN_A_ROW}): a loaded host can stall the simulated actuators "
                      "past their watchdog. A measurement a fault interrupted is never kept; the faults recovered "
                      "from are counted at the end")


def run_demo_command(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import ServiceUnavailable
    from hexactl.application.campaign.driver import CampaignError
    from hexactl.application.campaign.progress import Progress
    from hexactl.application.campaign.store import DirectoryError
    from hexactl.application.demo import DemoSettings, clear_results, run_demo
    from hexactl.application.service import ServiceError

    check_campaign_arguments(arguments)
    check_writable(arguments.out, folder=True)
    if arguments.force:
        clear_results(arguments.out)
    settings = DemoSettings(arguments.out, arguments.seed, arguments.per_leg, arguments.envelope,
                            Path(arguments.config) if arguments.config else None, arguments.reset_faults,
                            checked_http(arguments.dashboard))
    progress = Progress()
    try:
        outcome = run_demo(settings, progress)
    except (DirectoryError, ServiceError) as error:
        raise CliError(f"{error}" + (" (or --force)" if isinstance(error, DirectoryError) else "")) from None
    except ServiceUnavailable as error:  # its own service: too starved to answer, or dead
        return campaign_stopped("demo", CampaignError(f"the demo's service stopped answering ({error}); what was "
                                                      f"measured is saved in {arguments.out}: run the same command "
                                                      "again to resume"), arguments.out, progress)
    except (CampaignError, KeyboardInterrupt) as stopped_by:
        return campaign_stopped("demo", stopped_by, arguments.out, progress)
    return 0 if outcome.improved else 1
