"""Create a sweep directory with ``visnav-sweep``'s own options, without running it.

    python tools/device/make_sweep.py --set randomize_look=true --grid aux_depth=0,1 \
        --seeds 5-8 --no-baselines --name l2-looks-depth-dev

The folder (``runs/NAME``) is then run elsewhere by ``run_sweep.py``, and its report is
aggregated back here with ``visnav-sweep --aggregate runs/NAME``.
"""

from __future__ import annotations

import sys

from nav_eval.sweep import build_parser
from nav_eval.sweeps.spec import spec_from_args

if __name__ == '__main__':
    spec = spec_from_args(build_parser().parse_args(sys.argv[1:]))
    print(f'{spec.sweep_dir}: {len(spec.trials())} trials')
