"""The Gymnasium env: ``navigation`` (NavigationEnv, a ROS 2 client of the sim node) and its parts.

``config`` (EnvConfig), ``reward`` (the reward as a pure function: no ROS, no MuJoCo, no
torch), ``actions``, ``observation`` (camera image to observation), ``observers`` and
``live_view`` (what the live view and the bags keep of an episode) and ``checks`` (the
workshop's validation checklist).  This package imports none of them: importing the reward
does not import the env.
"""
