"""What a run reports: Prometheus metrics, the console progress line, learning curves,
TensorBoard event files and `wmdist monitor`."""
