"""The files both halves of the toolkit share, and nothing else: one place for each format.

``synth`` writes them and ``reloc`` reads them; this package imports neither.

* ``errors``: user errors (one line, exit status 2) and output-folder checks;
* ``atomic``: atomic writes (text, JSON, NPZ, figures): no half-written file is ever visible;
* ``yamlfile``: reading users' YAML and JSON files, errors naming file, line and column;
* ``camera``: camera conventions (OpenCV axes, intrinsics, camera-to-world poses, quaternions) and
  TUM trajectories;
* ``frames``: the EXR frame format (RGB, planar depth, instance and semantic ids) and sRGB;
* ``boxes``: the box format (``videoreloc-boxes/1``) of ground truth and maps, and the instance id bases;
* ``tour``: the tour folder format and its reader, ``Tour``;
* ``environment``: what produced a result (toolkit version and commit, machine, library versions);
* ``native``: imports of wheels that link system libraries (open3d): a missing one is one line;
* ``design``: a rendered design (``design.json``, tour names), listed from its tours' meta.json.
"""
