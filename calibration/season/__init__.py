"""A season: the calibrated antenna spectra of many runs, binned in local sidereal time.

``binning`` holds the per-run work (one run file's spectra read, weighted and summed per
LST bin: a pure function of the file) and the sum of those parts into the season's
averages with their error in two parts; ``season_file`` the self-describing HDF5;
``gsdata`` the export to the 21-cm community's ``GSData`` container (``pygsdata``).
The archive on Dask: ``chunks`` reads a run's spectra in chunks of rows, ``archive``
runs the season as a graph over runs and chunks on a local or existing cluster,
``recalibrate`` calibrates a run's antenna cycles again with a new solution as the
observe step did, and ``archive_apply`` does that over many runs, resumably.
"""
