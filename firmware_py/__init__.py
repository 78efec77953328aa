"""The controller: the firmware and what a controller process needs around it.

* ``model_regulator``: the porting reference, the limited-integrator model regulator of
  eqs. (6)-(8), (18) and (22) as a fixed-step scalar ``step()``; imports the standard library only.
* ``plausibility``, ``authority``: porting references in the same style: the plausibility
  monitor (the inputs against each other and the nominal car) and the bounded authority.
* ``controller``: the controller process (receive, freshness, ``step()``, command, status).
* ``platform``: what any bus process needs: opening a bus, the fallback bus, command-line
  conventions, output files, process life, real-time set-up.
"""
