"""Quality checks of the benchmark itself: solvability of every persona x task, fidelity of the users."""
