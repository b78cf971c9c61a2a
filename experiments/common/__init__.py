"""What the commands share: the study flags (`studyargs`), the PARS training settings
(`training`), the evaluation of a controller (`evaluation`) and the learning curves
(`curves`). No command lives here, and no command imports another
(tests/test_architecture.py)."""
