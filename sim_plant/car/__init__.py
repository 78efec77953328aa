"""The car and what it plays.

* ``vehicle``: the paper's linear single-track model (eqs. 14/16), exact ZOH discretisation.
* ``tyres``, ``nonlinear``: magic-formula tyres and the nonlinear single-track model
  (``NonlinearPlant``; ``BatchCar`` the same over a batch of numpy arrays, the campaign's).
* ``plants``: one interface over the linear and the nonlinear car, with the disturbance loads.
* ``disturbances``: split-μ braking, side-wind gust, tyre blow-out.
* ``actuator``: the actuator's handling of commands (timeout, fade, slew back, ±3°);
  ``actuator_dynamics``: its position response (lag, rate limit, dead time; ``BatchPositionActuator``
  the first order's over a batch).
* ``sensors``: noise, bias, low-pass and DBC quantisation of the measurements (and of the
  redundant ones: lateral acceleration, the second steering channel); ``sensor_faults``: wrong
  values in well-formed frames (stuck, bias, scale, drift, noise, frozen).
* ``scenario``: operating point, events, driver model; built-ins and TOML files;
  ``scenario_play`` plays one step by step (``ScenarioState``);
  ``model_files``: reading the actuator and sensor TOML files.
* ``options``: the command-line options that choose the car.

``docs/realistic-car.md`` describes the models.
"""
