"""The closed-loop rig, by concern, in the order a frame flows (each subpackage's own
docstring says what it owns and what it may import; ``make lint`` checks the layers):

- :mod:`rig.scenarios`: what a run is asked to do (scenario files, the command script,
  fault injection);
- :mod:`rig.chips`: the emulated sensor chips between the model and the autopilot (TLM
  register models, the RTL under cocotb and its channel, the PWM outputs and capture);
- :mod:`rig.mavlink`: PX4's simulator API and the links that speak it (simulator TCP,
  HIL messages, the scenario's ground link);
- :mod:`rig.autopilots`: the flight controllers on the other side (PX4 SITL, started from
  the user's build; the reference autopilot, a separate process);
- :mod:`rig.logs`: ULog writing (``rig.ulg``);
- :mod:`rig.lockstep`: the loop that ties one frame together;
- :mod:`rig.plots` and :mod:`rig.view`: a run's plots and its page in the browser, live
  or played back;
- :mod:`rig.identify`: a vehicle's parameters, the wind and the IMU's vibration from a
  flight log;
- :mod:`rig.replay` and :mod:`rig.campaign`: a real flight flown again, and many runs
  swept over a campaign's axes;
- :mod:`rig.cli`: the ``rig`` command, one module per command.

Flight logs are read through :mod:`px4_logs`, the package under both the rig and
``credibility``.

:mod:`rig.errors` and :mod:`rig.processes` serve every layer.
"""
