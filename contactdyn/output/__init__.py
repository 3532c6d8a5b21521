"""What a run leaves: the sampled channels, the Result and its files, the run's own physics checks,
metrics, plots and the warnings of what a run did not do."""
