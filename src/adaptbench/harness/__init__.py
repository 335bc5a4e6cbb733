"""The episode harness: rollouts over personas x tasks x seeds, results files, evaluation tables and plots."""
