"""The calibration as a declared sequence of stages (`sequence.STAGE_SEQUENCE`).

A stage takes the `CalibrationState` and the config and returns the new state with its details
(`runner.StageOutcome`); `runner.run_stages` runs them in order, timing and reporting each.
`setup.initial_state` makes the state the first stage starts from."""
