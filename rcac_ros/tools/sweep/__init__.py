"""Monte Carlo campaigns (doc/campaigns.md): the campaign file and one run (campaign), the
runs on Dask (engine), the results directory (store), the summary and rerun (report), the
bench (bench) and the ``rcac sweep`` command line (commands)."""
