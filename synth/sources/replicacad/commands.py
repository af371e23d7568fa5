"""``synth scene import-replicacad``: a ReplicaCAD scene instance to a layout file (docs/replicacad.md). Not
named ``cli``: it imports only downwards (the importer, the scene model), so it sits in the sources layer
and the source object (``source.register_scene_cli``) may import it."""

from __future__ import annotations


def cmd_import_replicacad(args) -> int:
    from ...scene.model import save_layout
    from .importer import load_replicacad

    lay = load_replicacad(args.root, args.scene, allow_unknown=args.allow_unknown, structure=not args.no_structure)
    out = save_layout(lay, args.out)
    st = lay.stage
    print(f"wrote {out}: {len(lay.objects)} objects in {len({o.cls for o in lay.objects})} classes; stage: "
          f"{len(st.walls)} walls, {len(st.rooms)} rooms, {len(st.openings)} openings, {len(lay.fixtures)} light fixtures")
    return 0


def register_scene_cli(ss) -> None:
    """The source's commands in the ``synth scene`` group (``ss``: its subparsers)."""
    a = ss.add_parser("import-replicacad", help="convert a ReplicaCAD scene instance to a layout file")
    a.add_argument("root", help="ReplicaCAD dataset folder (holds configs/)")
    a.add_argument("scene", help="scene instance name, e.g. apt_0")
    a.add_argument("--out", required=True)
    a.add_argument("--allow-unknown", action="store_true", help="map unknown templates to class 'other'")
    a.add_argument("--no-structure", action="store_true",
                   help="keep the stage one mesh: no walls, rooms or openings derived from it, no articulated objects, "
                        "no fixtures (camera paths and variants then cannot be planned)")
    a.set_defaults(fn=cmd_import_replicacad)
