"""Teach-in: from LED detections of two cameras to the dancer's generalized coordinates.

Pure Python/numpy, SI units at every interface (m, rad, s; pixels for image data).
One concept per module (see ``docs/teach.md``):

* :mod:`.camera`       - ideal and improved camera model (eq. 4.1-4.7, 4.15-4.23)
* :mod:`.calibration`  - camera parameters from known markers (eq. 4.8-4.9)
* :mod:`.triangulate`  - object points from two or more cameras (eq. 4.10-4.14)
* :mod:`.rucksack`     - generalized coordinates of the four-LED rucksack (eq. 5.1-5.7)
* :mod:`.filters`      - syntactic and semantic filters (section 6)
* :mod:`.axis_map`     - generalized coordinates -> figure axes
* :mod:`.recording`    - CSV of per-field LED detections
* :mod:`.synthetic`    - synthetic ground truth
* :mod:`.pipeline`     - the steps chained together
* :mod:`.markers`      - CSV of calibration markers
* :mod:`.guess`        - linear starting guess of a camera from its markers
* :mod:`.camera_file`  - cameras.toml (written by calibrate, read by teach)
* :mod:`.settings`     - teach settings TOML (rucksack, filters, areas, axis map)
* :mod:`.make_sample`  - the bundled sample recording and its generator

Submodules are imported explicitly (``from marionette.teach.camera import ...``).
"""
