"""Validation campaigns: thousands of randomised scenarios on the realistic car, in batches.

* ``params``: the sampled parameters, a ``SampleSet``, the scenario one sample is;
* ``spec``: the campaign file (TOML): distributions, sample count, calibrations, criteria;
* ``sampling``: Latin hypercube or random designs, every sample a function of its index;
* ``batch_sensors``, ``loads``: the sensors and the disturbances vectorised (the car and the
  actuator are ``sim_plant.car``'s array models: ``nonlinear.BatchCar``,
  ``actuator_dynamics.BatchPositionActuator``); ``noise``: the sensors' per-row noise streams, seeded and drawn as
  the scalar sensors draw them;
* ``c_cycle``: the C port's control cycle over a batch's rows (``ports/c/mrs_cycle_batch.c``,
  compiled with cffi at install), and the actuators' own authority limiters;
* ``engine``: the closed loop over a batch; ``batch_tally``: its figures per row, each row's run
  to its end (a spin ends it); ``batch_faults``: the sampled sensor faults and their figures;
* ``reference``: the same closed loop from the product's scalar classes, as the controller node
  runs them (the engine's oracle);
* ``results``: a chunk's table, the criteria, Parquet files; ``runner``: chunks on Dask, resume;
* ``report``: pass rates, maps, histograms, worst cases; ``export``: a sample as a scenario file.

``docs/campaigns.md`` describes the campaign file and the commands.
"""
