"""Floor 3, the stage services: what every stage needs and no stage owns.

* ``data``: the configured log read once (one cache), the benchmark splits cut from it, the sensor's far bound;
* ``outputs``: stage folders, settings keys, manifests (digests of config, inputs and outputs), JSON and figures
  written atomically, ``up_to_date``;
* ``metrics``: the metrics the stages compute (IR-MCL's localization protocol, relations, scan synthesis);
* ``filters``: the one factory of the particle filter (a config and a map in, a filter out);
* ``nog``: a checkpoint's NOG baked once and cached; ``plots``: the figures stages share.

Stages (floor 4) sit on these; these sit on the algorithms (floor 2) and io / kernels (floor 1).
"""
