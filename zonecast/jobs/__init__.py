"""Jobs: the pipelines behind the CLI commands (reproduce the paper, diagnosis report,
identify, forecast). They call the estimator through :class:`zonecast.estimator.pipeline.Pipeline`
and never import service internals."""
