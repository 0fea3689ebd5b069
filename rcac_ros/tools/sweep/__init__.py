"""Monte Carlo campaigns: the campaign file and one run, the Dask engine, store and report
(doc/campaigns.md)."""
