"""Scene builders the add-on itself needs (the report's hard-case scenes), shared with the
tests and benchmarks."""

import bpy


def bsdf_material(name: str, node_type: str, **inputs):
    """A new material whose surface is one BSDF node (e.g. ``"ShaderNodeBsdfGlossy"``);
    ``inputs`` by socket name, ``distribution=`` sets the node's distribution."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nt = mat.node_tree
    for node in list(nt.nodes):
        if node.type == "BSDF_PRINCIPLED":
            nt.nodes.remove(node)
    node = nt.nodes.new(node_type)
    for key, value in inputs.items():
        if key == "distribution":
            node.distribution = value
        else:
            node.inputs[key].default_value = value
    out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
    nt.links.new(node.outputs[0], out.inputs["Surface"])
    return mat
