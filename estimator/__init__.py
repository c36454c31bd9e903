"""Pure numerics: site, model, filter, identification, forecasts (no I/O beyond files)."""
