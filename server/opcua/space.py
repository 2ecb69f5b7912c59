"""The address space: one Robotics ``MotionDeviceSystem`` per controller, frames in pendant's namespace.

OPC 40010-1 (Robotics) defines MotionDeviceSystemType with MotionDevices, Controllers and
SafetyStates; a MotionDevice has Axes (ActualPosition), PowerTrains and FlangeLoad
(LoadType: Mass, CenterOfMass, Inertia); a Controller has CurrentUser. The specification has
no tool or base frame types, so the 16 tool and 32 base slots live in pendant's own
namespace as OPC 10000-5 ``3DFrameType`` variables (§7.28; the 3DFrame data type, §12.27).

Orientation: OPC UA's 3DOrientation is A about X (roll), B about Y (pitch), C about Z (yaw)
applied as intrinsic z-y'-x'' (OPC 10000-5 Amd. 11 §12.29; OPC 10000-210 Annex B). KUKA's
A is about Z and its C about X, so OPC's A is KUKA's C and OPC's C is KUKA's A (same
rotation, see :func:`opc_orientation`). docs/opcua.md has the tree.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, fields
from datetime import UTC, datetime
from pathlib import Path

from asyncua import Node, Server, ua
from asyncua.common.instantiate_util import instantiate
from asyncua.server.address_space import AttributeValue, NodeData

from server.opcua.state import ControllerState, EventState, SlotState

NODESETS = Path(__file__).resolve().parent / "nodesets"
DI_URI = "http://opcfoundation.org/UA/DI/"
ROBOTICS_URI = "http://opcfoundation.org/UA/Robotics/"
PENDANT_URI = "urn:pendant:opcua"

# Robotics type ids (ns=Robotics), from Opc.Ua.Robotics.NodeSet2.xml
MOTION_DEVICE_SYSTEM_TYPE = 1002
LOAD_TYPE = 1018
MOTION_DEVICE_CATEGORY_ARTICULATED_ROBOT = 1  # MotionDeviceCategoryEnumeration
AXIS_MOTION_PROFILE_ROTARY = 1  # AxisMotionProfileEnumeration: 0 OTHER, 1 ROTARY (bounded), 2 ROTARY_ENDLESS


def opc_orientation(a_deg: float, b_deg: float, c_deg: float) -> tuple[float, float, float]:
    """OPC UA (A, B, C) of a KUKA (A, B, C): R = Rz(A_k) Ry(B_k) Rx(C_k) = Rz(C_o) Ry(B_o) Rx(A_o).

    >>> opc_orientation(30.0, -10.0, 5.0)
    (5.0, -10.0, 30.0)
    """
    return (c_deg, b_deg, a_deg)


async def load_nodesets(server: Server) -> tuple[int, int, int]:
    """Import DI, then Robotics; register pendant's namespace. Returns (di, robotics, pendant)."""
    await server.import_xml(str(NODESETS / "Opc.Ua.Di.NodeSet2.xml"))
    await server.import_xml(str(NODESETS / "Opc.Ua.Robotics.NodeSet2.xml"))
    di = await server.get_namespace_index(DI_URI)
    rob = await server.get_namespace_index(ROBOTICS_URI)
    ns = await server.register_namespace(PENDANT_URI)
    await namespace_metadata(server, ns)
    return di, rob, ns


# The date pendant's namespace model (the PendantEventType, the NodeId scheme of
# docs/opcua.md) was last published: move it with a change to either.
PENDANT_NAMESPACE_PUBLISHED = datetime(2026, 11, 27, tzinfo=UTC)
# String NodeIds of static Nodes (OPC 10000-5 §6.3.13: identical in every server of this
# NamespaceVersion): the metadata object below and its properties. Instance nodes are not.
PENDANT_STATIC_STRING_IDS = r"^NamespaceMetadata(\.[A-Za-z]+)?$"


async def namespace_metadata(server: Server, ns: int) -> Node:
    """Server/Namespaces' ``NamespaceMetadataType`` object for pendant's namespace (OPC 10000-5
    §6.3.13-14), beside the ones the DI and Robotics nodesets bring.

    Static Nodes are the same in every server, Value included: here the PendantEventType
    and its properties (Numeric ids, handed out in the same order at every start) and this
    object's properties. Every controller's node (String ids of docs/opcua.md) is live data,
    so String is not a static IdType; ``StaticStringNodeIdPattern`` names the static ones.
    """
    from server import __version__

    meta = (await instantiate(
        server.get_node(ua.ObjectIds.Server_Namespaces),
        server.get_node(ua.ObjectIds.NamespaceMetadataType),
        nodeid=ua.NodeId("NamespaceMetadata", ns), bname=ua.QualifiedName(PENDANT_URI, ns),
        dname=ua.LocalizedText(PENDANT_URI), instantiate_optional=False))[0]
    values = {
        "NamespaceUri": ua.Variant(PENDANT_URI, ua.VariantType.String),
        "NamespaceVersion": ua.Variant(__version__, ua.VariantType.String),
        "NamespacePublicationDate": ua.Variant(PENDANT_NAMESPACE_PUBLISHED, ua.VariantType.DateTime),
        "IsNamespaceSubset": ua.Variant(False, ua.VariantType.Boolean),
        "StaticNodeIdTypes": ua.Variant([ua.IdType.Numeric], ua.VariantType.Int32),
        "StaticNumericNodeIdRange": ua.Variant([], ua.VariantType.String),
        "StaticStringNodeIdPattern": ua.Variant(PENDANT_STATIC_STRING_IDS, ua.VariantType.String),
    }
    for name, value in values.items():
        await (await meta.get_child(f"0:{name}")).write_value(value)
    return meta


@dataclass
class SlotNodes:
    name: Node
    kind: Node
    frame: Node
    coords: Node
    orient: Node
    xyz: tuple[Node, Node, Node]
    abc: tuple[Node, Node, Node]
    mass: Node
    version: Node
    method: Node
    error_rms: Node
    error_max: Node
    updated_at: Node


@dataclass
class CellNodes:
    """Handles on the variables that follow a controller's state."""

    system: Node
    pendant: Node
    axes: list[Node]
    flange_mass: Node
    flange_com_frame: Node  # 3DFrame: the CenterOfMass, orientation 0
    flange_com_coords: Node  # its CartesianCoordinates (3DCartesianCoordinates)
    flange_inertia_vector: Node  # 3DVector: the principal moments
    flange_com: tuple[Node, Node, Node]
    flange_inertia: tuple[Node, Node, Node]
    current_user: Node
    active_tool: Node
    active_base: Node
    sessions: Node
    slots: dict[tuple[str, int], SlotNodes] = field(default_factory=dict)


async def _child(node: Node, *path: str) -> Node:
    return await node.get_child(list(path))


async def _fill_placeholders(parent: Node, names: dict[str, list[str]], ns: int) -> None:
    """Replace each ``<...Identifier>`` child asyncua instantiated by real instances, recursively."""
    for child in await parent.get_children(refs=ua.ObjectIds.HierarchicalReferences):
        bname = await child.read_browse_name()
        if bname.Name.startswith("<") and bname.Name.endswith(">"):
            type_def = await child.read_type_definition()
            await remove(child)
            for real in names.get(bname.Name, []):
                made = await instantiate(parent, Node(parent.session, type_def),
                                         nodeid=ua.NodeId(f"{parent.nodeid.Identifier}.{real}", ns),
                                         bname=ua.QualifiedName(real, bname.NamespaceIndex),
                                         dname=ua.LocalizedText(real), instantiate_optional=False)
                await _fill_placeholders(made[0], names, ns)
        elif await child.read_node_class() == ua.NodeClass.Object:
            await _fill_placeholders(child, names, ns)


async def remove(node: Node) -> None:
    """Delete ``node`` and everything below it.

    asyncua's ``delete(delete_references=True)`` scans the whole address space for every
    deleted node; only the parent points into the subtree, so unlink that one reference and
    delete the subtree without the scan.
    """
    for ref in await node.get_references(ua.ObjectIds.HierarchicalReferences,
                                         ua.BrowseDirection.Inverse):
        parent = Node(node.session, ref.NodeId)
        await parent.delete_reference(node, ref.ReferenceTypeId, forward=True, bidirectional=True)
    await node.delete(delete_references=False, recursive=True)


async def _set(node: Node, value: object, variant: ua.VariantType) -> None:
    """Write a value with its SourceTimestamp (when the face saw it in the database)."""
    await node.write_value(ua.DataValue(ua.Variant(value, variant),
                                        SourceTimestamp=datetime.now(UTC)))


async def add_cell(server: Server, ns_ids: tuple[int, int, int], st: ControllerState,
                   templates: dict | None = None,
                   methods: tuple[tuple[str, list[ua.Argument], list[ua.Argument]], ...] = ()
                   ) -> CellNodes:
    """The controller's MotionDeviceSystem, its pendant frames object (and ``methods``' nodes,
    linked by the caller), filled with ``st``'s values.

    asyncua's ``instantiate`` browses the nodeset's types for every node it makes (about a
    second a cell). The first cell of a shape (its axis count, its slots) is built that way
    once, as a :class:`CellTemplate` under placeholder names, and taken out of the address
    space; every cell is then a copy of it with its own NodeIds and names (a few ms, no
    browse), in ``templates`` (a dict the caller keeps) for the next one."""
    templates = {} if templates is None else templates
    shape = (len(st.joints_deg), tuple((s.table, s.number) for s in st.slots),
             tuple(m[0] for m in methods))
    tpl = templates.get(shape)
    if tpl is None:
        tpl = templates[shape] = await CellTemplate.build(server, ns_ids, st, methods)
    return await tpl.copy(server, st)


# placeholders of a template's names, in Unicode's private use area (no controller has them)
P_NAME, P_ROBOT, P_CREATED = "\ue000controller\ue000", "\ue000robot\ue000", "\ue000created\ue000"


@dataclass
class Subtree:
    """A snapshot of a node and everything below it (asyncua's NodeData), out of the space."""

    root: ua.NodeId
    parent: ua.NodeId
    parent_ref: ua.ReferenceDescription  # the parent's forward reference to the root
    nodes: list[NodeData]

    @classmethod
    def take(cls, aspace, root: ua.NodeId) -> Subtree:
        """Take ``root`` and every node below it whose string NodeId starts with ``root``'s
        and a dot (the face's NodeIds are paths: a type's nodes are not taken) out of
        ``aspace``."""
        prefix = f"{root.Identifier}."
        ids, seen = [root], {root}
        for nid in ids:  # grows as it goes: breadth first over forward references
            for r in aspace[nid].references:
                t = r.NodeId
                if r.IsForward and t not in seen and t.NamespaceIndex == root.NamespaceIndex \
                        and isinstance(t.Identifier, str) and t.Identifier.startswith(prefix):
                    seen.add(t)
                    ids.append(t)
        nodes = [aspace[n] for n in ids]
        (up,) = [r for r in nodes[0].references
                 if not r.IsForward and r.ReferenceTypeId != ua.NodeId(ua.ObjectIds.HasTypeDefinition)]
        parent = aspace[up.NodeId]
        (down,) = [r for r in parent.references if r.IsForward and r.NodeId == root]
        parent.references.remove(down)
        for n in ids:
            del aspace[n]
        return cls(root, up.NodeId, down, nodes)

    def copy(self, aspace, rename) -> ua.NodeId:
        """Add a copy: every NodeId, BrowseName and DisplayName through ``rename`` (a str
        function, applied where a placeholder is); its root's NodeId."""
        ns = self.root.NamespaceIndex
        ids = {nd.nodeid: ua.NodeId(rename(nd.nodeid.Identifier), ns) for nd in self.nodes}
        for nid in ids.values():
            if nid in aspace:
                raise RuntimeError(f"OPC UA node {nid} not added: BadNodeIdExists")
        made = []
        for nd in self.nodes:
            new = NodeData(ids[nd.nodeid])
            for attr, av in nd.attributes.items():
                dv = av.value
                if attr == ua.AttributeIds.NodeId:
                    dv = ua.DataValue(ua.Variant(new.nodeid, ua.VariantType.NodeId))
                elif attr == ua.AttributeIds.BrowseName and "\ue000" in dv.Value.Value.Name:
                    q = dv.Value.Value
                    dv = ua.DataValue(ua.Variant(ua.QualifiedName(rename(q.Name), q.NamespaceIndex),
                                                 ua.VariantType.QualifiedName))
                elif attr == ua.AttributeIds.DisplayName and "\ue000" in (dv.Value.Value.Text or ""):
                    dv = ua.DataValue(ua.Variant(ua.LocalizedText(rename(dv.Value.Value.Text)),
                                                 ua.VariantType.LocalizedText))
                new.attributes[attr] = AttributeValue(dv)
            new.references = [_renamed_ref(r, ids.get(r.NodeId, r.NodeId), rename)
                              for r in nd.references]
            made.append(new)
        for new in made:
            aspace[new.nodeid] = new
        root = ids[self.root]
        aspace[self.parent].references.append(_renamed_ref(self.parent_ref, root, rename))
        return root


def _renamed_ref(r: ua.ReferenceDescription, target: ua.NodeId, rename) -> ua.ReferenceDescription:
    bname, dname = r.BrowseName, r.DisplayName
    if "\ue000" in bname.Name:
        bname = ua.QualifiedName(rename(bname.Name), bname.NamespaceIndex)
    if "\ue000" in (dname.Text or ""):
        dname = ua.LocalizedText(rename(dname.Text))
    return ua.ReferenceDescription(ReferenceTypeId=r.ReferenceTypeId, IsForward=r.IsForward,
                                   NodeId=target, BrowseName=bname, DisplayName=dname,
                                   NodeClass=r.NodeClass, TypeDefinition=r.TypeDefinition)


def remove_ids(server: Server, root: ua.NodeId) -> int:
    """Delete ``root`` and every node whose NodeId is ``root``'s and a dot (a cell's subtree),
    without asyncua's per-node browse; a subscriber of one of them hears BadNodeIdUnknown.
    Returns how many nodes went."""
    aspace = server.iserver.aspace
    if root not in aspace:
        return 0
    sub = Subtree.take(aspace, root)
    for nd in sub.nodes:  # the subscriptions' callbacks, as asyncua's delete calls them
        aspace[nd.nodeid] = nd
    server.iserver.node_mgt_service.delete_nodes(ua.DeleteNodesParameters(NodesToDelete=[
        ua.DeleteNodesItem(NodeId=nd.nodeid, DeleteTargetReferences=False) for nd in sub.nodes]))
    return len(sub.nodes)


@dataclass
class CellTemplate:
    """A cell built once under placeholder names (:data:`P_NAME`, :data:`P_ROBOT`), out of
    the address space: its two subtrees and its handles; :meth:`copy` makes a cell of it."""

    key: str  # the template's node_key
    system: Subtree
    pendant: Subtree
    nodes: CellNodes  # the handles, on the template's NodeIds
    identity: dict[str, Node]  # the variables :func:`_identity_values` fills

    @classmethod
    async def build(cls, server: Server, ns_ids: tuple[int, int, int], like: ControllerState,
                    methods) -> CellTemplate:
        from dataclasses import replace

        st = replace(like, name=P_NAME, robot_name=P_ROBOT, created_at=P_CREATED)
        nodes, identity = await _build_cell(server, ns_ids, st)
        for name, inputs, outputs in methods:
            await add_method_node(server, nodes.pendant, name, ns_ids[2], inputs, outputs)
        aspace = server.iserver.aspace
        return cls(st.node_key, Subtree.take(aspace, nodes.system.nodeid),
                   Subtree.take(aspace, nodes.pendant.nodeid), nodes, identity)

    async def copy(self, server: Server, st: ControllerState) -> CellNodes:
        key = self.key

        def rename(s: str) -> str:
            return s.replace(key, st.node_key).replace(P_NAME, st.name).replace(P_ROBOT, st.robot_name)

        aspace = server.iserver.aspace
        self.system.copy(aspace, rename)
        try:
            self.pendant.copy(aspace, rename)
        except Exception:
            remove_ids(server, ua.NodeId(rename(self.system.root.Identifier), self.system.root.NamespaceIndex))
            raise

        def moved(n: Node) -> Node:
            return server.get_node(ua.NodeId(rename(n.nodeid.Identifier), n.nodeid.NamespaceIndex))

        nodes = _map_nodes(self.nodes, moved)
        values = _identity_values(st)
        await write_many([(moved(self.identity[k]), v, t) for k, (v, t) in values.items()])
        await update_cell(nodes, None, st)
        return nodes


def _map_nodes(obj, moved):
    """``obj`` (CellNodes, SlotNodes, a tuple, list or dict of them) with every Node moved."""
    if isinstance(obj, Node):
        return moved(obj)
    if isinstance(obj, tuple):
        return tuple(_map_nodes(o, moved) for o in obj)
    if isinstance(obj, list):
        return [_map_nodes(o, moved) for o in obj]
    if isinstance(obj, dict):
        return {k: _map_nodes(v, moved) for k, v in obj.items()}
    return type(obj)(**{f.name: _map_nodes(getattr(obj, f.name), moved) for f in fields(obj)})


async def _build_cell(server: Server, ns_ids: tuple[int, int, int], st: ControllerState
                      ) -> tuple[CellNodes, dict[str, Node]]:
    """Instantiate the controller's MotionDeviceSystem and its pendant frames object the slow
    way (asyncua's ``instantiate``); its handles and identity variables."""
    di, rob, ns = ns_ids
    device_set = await server.nodes.objects.get_child([f"{di}:DeviceSet"])
    dof = len(st.joints_deg)
    names = {"<MotionDeviceIdentifier>": [st.robot_name], "<ControllerIdentifier>": [st.name],
             "<SafetyStateIdentifier>": ["SafetyState"],
             "<AxisIdentifier>": [f"A{i + 1}" for i in range(dof)],
             "<PowerTrainIdentifier>": [f"PT{i + 1}" for i in range(dof)],
             "<MotorIdentifier>": ["Motor"], "<GearIdentifier>": ["Gear"],
             "<SoftwareIdentifier>": ["pendant"], "<TaskControlIdentifier>": ["Calibration"]}
    system = (await instantiate(
        device_set, server.get_node(ua.NodeId(MOTION_DEVICE_SYSTEM_TYPE, rob)),
        nodeid=ua.NodeId(st.node_key, ns), bname=ua.QualifiedName(st.name, ns),
        dname=ua.LocalizedText(st.name), instantiate_optional=False))[0]
    await _fill_placeholders(system, names, ns)

    device = await _child(system, f"{rob}:MotionDevices", f"{rob}:{st.robot_name}")
    await _set(await _child(device, f"{rob}:MotionDeviceCategory"),
               MOTION_DEVICE_CATEGORY_ARTICULATED_ROBOT, ua.VariantType.Int32)
    axes = []
    for i in range(dof):
        axis = await _child(device, f"{rob}:Axes", f"{rob}:A{i + 1}")
        await _set(await _child(axis, f"{rob}:MotionProfile"), AXIS_MOTION_PROFILE_ROTARY,
                   ua.VariantType.Int32)
        pos = await _child(axis, f"{di}:ParameterSet", f"{rob}:ActualPosition")
        await _set(pos, st.joints_deg[i], ua.VariantType.Double)
        await _set(await _child(pos, "0:EngineeringUnits"), UNITS["deg"],
                   ua.VariantType.ExtensionObject)
        axes.append(pos)

    load = (await instantiate(device, server.get_node(ua.NodeId(LOAD_TYPE, rob)),
                              nodeid=ua.NodeId(f"{device.nodeid.Identifier}.FlangeLoad", ns),
                              bname=ua.QualifiedName("FlangeLoad", rob),
                              dname=ua.LocalizedText("FlangeLoad"), instantiate_optional=True))[0]
    com = await _child(load, f"{rob}:CenterOfMass", "0:CartesianCoordinates")
    inertia = await _child(load, f"{rob}:Inertia")

    ctrl = await _child(system, f"{rob}:Controllers", f"{rob}:{st.name}")
    user = await _child(ctrl, f"{rob}:CurrentUser", f"{rob}:Level")
    identity = await _identity_nodes(system, device, ctrl, load, dof, ns_ids)
    values = _identity_values(st)
    await write_many([(identity[k], v, t) for k, (v, t) in values.items()])
    await _no_good_nulls(system)

    pendant, slot_ids = await _pendant_object(server, ns, st)
    nodes = CellNodes(
        system=system, pendant=pendant, axes=axes,
        flange_mass=await _child(load, f"{rob}:Mass"),
        flange_com_frame=await _child(load, f"{rob}:CenterOfMass"), flange_com_coords=com,
        flange_inertia_vector=inertia,
        flange_com=tuple([await _child(com, f"0:{k}") for k in "XYZ"]),  # type: ignore[arg-type]
        flange_inertia=tuple([await _child(inertia, f"0:{k}") for k in "XYZ"]),  # type: ignore[arg-type]
        current_user=user,
        active_tool=await _child(pendant, f"{ns}:ActiveTool"),
        active_base=await _child(pendant, f"{ns}:ActiveBase"),
        sessions=await _child(pendant, f"{ns}:Sessions"))
    nodes.slots = {key: _slot_nodes(server, ids) for key, ids in slot_ids.items()}
    await update_cell(nodes, None, st)
    return nodes, identity


async def write_many(writes: list[tuple[Node, object, ua.VariantType]]) -> None:
    """Write values with their SourceTimestamp (when the face saw them in the database) in
    one Write call of the server's own session (the nodes')."""
    if not writes:
        return
    now = datetime.now(UTC)
    params = ua.WriteParameters(NodesToWrite=[
        ua.WriteValue(NodeId=node.nodeid, AttributeId=ua.AttributeIds.Value,
                      Value=ua.DataValue(ua.Variant(value, variant), SourceTimestamp=now))
        for node, value, variant in writes])
    for (node, _v, _t), status in zip(writes, await writes[0][0].session.write(params)):
        if not status.is_good():
            raise RuntimeError(f"OPC UA write of {node.nodeid} refused: {status}")


UNECE = "http://www.opcfoundation.org/UA/units/un/cefact"
UNITS = {  # OPC 10000-8 §5.6.3: UNECE Rec. 20 codes, UnitId = the code's ASCII as an int
    "deg": ua.EUInformation(NamespaceUri=UNECE, UnitId=17476, DisplayName=ua.LocalizedText("°"),
                            Description=ua.LocalizedText("degree")),
    "mm": ua.EUInformation(NamespaceUri=UNECE, UnitId=5066068, DisplayName=ua.LocalizedText("mm"),
                           Description=ua.LocalizedText("millimetre")),
    "kg": ua.EUInformation(NamespaceUri=UNECE, UnitId=4933453, DisplayName=ua.LocalizedText("kg"),
                           Description=ua.LocalizedText("kilogram")),
    "degC": ua.EUInformation(NamespaceUri=UNECE, UnitId=4408652, DisplayName=ua.LocalizedText("°C"),
                             Description=ua.LocalizedText("degree Celsius")),
}
ORIENTATION_ORDER = ("A about X (roll), B about Y (pitch), C about Z (yaw), degrees; "
                     "R = Rz(C) Ry(B) Rx(A), intrinsic z-y'-x'' (OPC 10000-5 12.29). "
                     "KUKA's A is this C, KUKA's C this A.")
OPERATIONAL_MODE_T1 = 1  # OperationalModeEnumeration MANUAL_REDUCED_SPEED: a teach pendant's T1


async def _identity_nodes(system: Node, device: Node, ctrl: Node, load: Node, dof: int,
                          ns_ids: tuple[int, int, int]) -> dict[str, Node]:
    """The variables of :func:`_identity_values`, by its keys."""
    di, rob, _ns = ns_ids
    software = await _child(ctrl, f"{rob}:Software", f"{rob}:pendant")
    task = await _child(ctrl, f"{rob}:TaskControls", f"{rob}:Calibration")
    safety = await _child(system, f"{rob}:SafetyStates", f"{rob}:SafetyState", f"{di}:ParameterSet")
    orient = await _child(load, f"{rob}:CenterOfMass", "0:Orientation")
    paths: dict[str, tuple[Node, tuple[str, ...]]] = {
        "device.Manufacturer": (device, (f"{di}:Manufacturer",)),
        "device.Model": (device, (f"{di}:Model",)),
        "device.ProductCode": (device, (f"{di}:ProductCode",)),
        "device.SerialNumber": (device, (f"{di}:SerialNumber",)),
        "device.SpeedOverride": (device, (f"{di}:ParameterSet", f"{rob}:SpeedOverride")),
        "ctrl.Manufacturer": (ctrl, (f"{di}:Manufacturer",)),
        "ctrl.Model": (ctrl, (f"{di}:Model",)),
        "ctrl.ProductCode": (ctrl, (f"{di}:ProductCode",)),
        "ctrl.SerialNumber": (ctrl, (f"{di}:SerialNumber",)),
        "software.Manufacturer": (software, (f"{di}:Manufacturer",)),
        "software.Model": (software, (f"{di}:Model",)),
        "software.SoftwareRevision": (software, (f"{di}:SoftwareRevision",)),
        "task.ComponentName": (task, (f"{di}:ComponentName",)),
        "task.TaskProgramName": (task, (f"{di}:ParameterSet", f"{rob}:TaskProgramName")),
        "task.TaskProgramLoaded": (task, (f"{di}:ParameterSet", f"{rob}:TaskProgramLoaded")),
        "safety.EmergencyStop": (safety, (f"{rob}:EmergencyStop",)),
        "safety.ProtectiveStop": (safety, (f"{rob}:ProtectiveStop",)),
        "safety.OperationalMode": (safety, (f"{rob}:OperationalMode",)),
        "load.MassUnits": (load, (f"{rob}:Mass", "0:EngineeringUnits")),
        "load.Orientation": (orient, ()),
        **{f"load.Orientation.{k}": (orient, (f"0:{k}",)) for k in "ABC"},
    }
    for i in range(dof):
        motor = await _child(device, f"{rob}:PowerTrains", f"{rob}:PT{i + 1}", f"{rob}:Motor")
        paths[f"motor{i}.Manufacturer"] = (motor, (f"{di}:Manufacturer",))
        paths[f"motor{i}.Model"] = (motor, (f"{di}:Model",))
        paths[f"motor{i}.TemperatureUnits"] = (motor, (f"{di}:ParameterSet",
                                                       f"{rob}:MotorTemperature",
                                                       "0:EngineeringUnits"))
    return {k: (await _child(node, *path) if path else node) for k, (node, path) in paths.items()}


def _identity_values(st: ControllerState) -> dict[str, tuple[object, ua.VariantType]]:
    """The mandatory values an emulated cell knows (the robot catalogue: maker and model;
    pendant: the software; the emulator: T1, no stop, full speed). What it does not know (a
    motor's serial number, its temperature) reads ``BadNotReadable``: never a Good Null."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        revision = version("pendant")
    except PackageNotFoundError:
        revision = "unknown"
    maker = st.robot_name.split()[0]
    lt, s_, d = ua.VariantType.LocalizedText, ua.VariantType.String, ua.VariantType.Double
    b, ext = ua.VariantType.Boolean, ua.VariantType.ExtensionObject
    values: dict[str, tuple[object, ua.VariantType]] = {
        "device.Manufacturer": (ua.LocalizedText(maker), lt),
        "device.Model": (ua.LocalizedText(st.robot_name), lt),
        "device.ProductCode": (st.robot_key, s_),
        "device.SerialNumber": (f"emulated:{st.node_key}", s_),
        "device.SpeedOverride": (100.0, d),
        "ctrl.Manufacturer": (ua.LocalizedText("pendant"), lt),
        "ctrl.Model": (ua.LocalizedText(f"emulated {maker} controller"), lt),
        "ctrl.ProductCode": ("pendant-emulator", s_),
        "ctrl.SerialNumber": (f"emulated:{st.node_key}", s_),
        "software.Manufacturer": (ua.LocalizedText("pendant"), lt),
        "software.Model": (ua.LocalizedText("pendant"), lt),
        "software.SoftwareRevision": (revision, s_),
        "task.ComponentName": (ua.LocalizedText("Calibration"), lt),
        "task.TaskProgramName": ("calibration menus", s_),
        "task.TaskProgramLoaded": (True, b),
        "safety.EmergencyStop": (False, b),
        "safety.ProtectiveStop": (False, b),
        "safety.OperationalMode": (OPERATIONAL_MODE_T1, ua.VariantType.Int32),
        "load.MassUnits": (UNITS["kg"], ext),
        # the centre of mass frame's orientation: the flange's (the inertia is about its axes)
        "load.Orientation": (ua.ThreeDOrientation(), ext),
        **{f"load.Orientation.{k}": (0.0, d) for k in "ABC"},
    }
    for i in range(len(st.joints_deg)):
        values[f"motor{i}.Manufacturer"] = (ua.LocalizedText(maker), lt)
        values[f"motor{i}.Model"] = (ua.LocalizedText(f"{st.robot_name} A{i + 1} motor"), lt)
        values[f"motor{i}.TemperatureUnits"] = (UNITS["degC"], ext)
    return values


async def _no_good_nulls(node: Node) -> None:
    """Every variable below ``node`` still Null reads ``BadNotReadable`` (the emulator does
    not know it: a motor's serial number, its temperature)."""
    for child in await node.get_children(refs=ua.ObjectIds.HierarchicalReferences):
        cls = await child.read_node_class()
        if cls == ua.NodeClass.Variable:
            dv = await child.read_data_value(raise_on_bad_status=False)
            if dv.Value is None or dv.Value.Value is None:
                await child.write_value(ua.DataValue(
                    StatusCode=ua.StatusCode(ua.StatusCodes.BadNotReadable)))
        if cls in (ua.NodeClass.Object, ua.NodeClass.Variable):
            await _no_good_nulls(child)


async def _pendant_object(server: Server, ns: int, st: ControllerState
                          ) -> tuple[Node, dict[tuple[str, int], dict[str, ua.NodeId]]]:
    """Objects/Pendant/<controller>: the tables, the active frames, the sessions (one batch)."""
    root = await _pendant_root(server, ns)
    batch = NodeBatch(ns)
    obj = batch.obj(root.nodeid, st.name, in_folder=True, node_id=f"Pendant.{st.node_key}")
    folders = {"tool": batch.obj(obj, "Tools", folder=True),
               "base": batch.obj(obj, "Bases", folder=True)}
    I32 = ua.VariantType.Int32
    batch.var(obj, "ActiveTool", st.active_tool_no, I32, ua.ObjectIds.Int32)
    batch.var(obj, "ActiveBase", st.active_base_no, I32, ua.ObjectIds.Int32)
    batch.var(obj, "Sessions", [], ua.VariantType.String, ua.ObjectIds.String)
    batch.items[-1].NodeAttributes.ValueRank = ua.ValueRank.OneDimension
    slot_ids = {(s.table, s.number): _add_slot(batch, folders[s.table], s) for s in st.slots}
    await batch.commit(server)
    return server.get_node(obj), slot_ids


async def _pendant_root(server: Server, ns: int) -> Node:
    node_id = ua.NodeId("Pendant", ns)
    try:
        node = server.get_node(node_id)
        await node.read_browse_name()
        return node
    except ua.UaStatusCodeError:
        return await server.nodes.objects.add_folder(node_id, ua.QualifiedName("Pendant", ns))


class NodeBatch:
    """AddNodesItems collected and added in one call (asyncua's helpers browse per node)."""

    def __init__(self, ns: int) -> None:
        self.ns = ns
        self.items: list[ua.AddNodesItem] = []

    def obj(self, parent: ua.NodeId, name: str, folder: bool = False,
            in_folder: bool = False, node_id: str | None = None) -> ua.NodeId:
        attrs = ua.ObjectAttributes(DisplayName=ua.LocalizedText(name), EventNotifier=0)
        return self._add(parent, name, ua.NodeClass.Object, attrs,
                         ua.ObjectIds.FolderType if folder else ua.ObjectIds.BaseObjectType,
                         ua.ObjectIds.Organizes if in_folder else ua.ObjectIds.HasComponent,
                         node_id=node_id)

    def var(self, parent: ua.NodeId, name: str, value: object, variant: ua.VariantType,
            data_type: int, type_def: int = ua.ObjectIds.BaseDataVariableType,
            name_ns: int | None = None, description: str = "") -> ua.NodeId:
        attrs = ua.VariableAttributes(
            DisplayName=ua.LocalizedText(name), Value=ua.Variant(value, variant),
            Description=ua.LocalizedText(description or name),
            DataType=ua.NodeId(data_type), ValueRank=ua.ValueRank.Scalar,
            AccessLevel=ua.AccessLevel.CurrentRead.mask,
            UserAccessLevel=ua.AccessLevel.CurrentRead.mask)
        return self._add(parent, name, ua.NodeClass.Variable, attrs, type_def,
                         ua.ObjectIds.HasComponent, name_ns)

    def prop(self, parent: ua.NodeId, name: str, value: object, data_type: int) -> ua.NodeId:
        """A property (HasProperty, PropertyType) in namespace 0's browse names, as the
        standard types declare them (LengthUnit, AngleUnit)."""
        attrs = ua.VariableAttributes(
            DisplayName=ua.LocalizedText(name),
            Value=ua.Variant(value, ua.VariantType.ExtensionObject),
            DataType=ua.NodeId(data_type), ValueRank=ua.ValueRank.Scalar,
            AccessLevel=ua.AccessLevel.CurrentRead.mask,
            UserAccessLevel=ua.AccessLevel.CurrentRead.mask)
        return self._add(parent, name, ua.NodeClass.Variable, attrs, ua.ObjectIds.PropertyType,
                         ua.ObjectIds.HasProperty, 0)

    def _add(self, parent: ua.NodeId, name: str, cls: ua.NodeClass, attrs: object, type_def: int,
             ref: int, name_ns: int | None = None, node_id: str | None = None) -> ua.NodeId:
        node_id = ua.NodeId(node_id or f"{parent.Identifier}.{name}", self.ns)
        self.items.append(ua.AddNodesItem(
            ParentNodeId=parent, ReferenceTypeId=ua.NodeId(ref),
            RequestedNewNodeId=node_id,
            BrowseName=ua.QualifiedName(name, self.ns if name_ns is None else name_ns),
            NodeClass=cls, NodeAttributes=attrs, TypeDefinition=ua.NodeId(type_def)))
        return node_id

    async def commit(self, server: Server) -> None:
        results = await server.iserver.isession.add_nodes(self.items)
        for item, r in zip(self.items, results):
            if not r.StatusCode.is_good():
                raise RuntimeError(f"OPC UA node {item.RequestedNewNodeId} not added: {r.StatusCode}")


def _add_slot(batch: NodeBatch, folder: ua.NodeId, s: SlotState) -> dict[str, ua.NodeId]:
    """One slot: an object with its 3DFrameType variable (OPC 10000-5 §7.28) and its values."""
    O, S, D = ua.ObjectIds, ua.VariantType.String, ua.VariantType.Double
    obj = batch.obj(folder, f"{'Tool' if s.table == 'tool' else 'Base'}{s.number}", in_folder=True)
    frame = batch.var(obj, "Frame", _frame_value(s.pose), ua.VariantType.ExtensionObject,
                      O.ThreeDFrame, O.ThreeDFrameType)
    coords = batch.var(frame, "CartesianCoordinates", _frame_value(s.pose).CartesianCoordinates,
                       ua.VariantType.ExtensionObject, O.ThreeDCartesianCoordinates,
                       O.ThreeDCartesianCoordinatesType, name_ns=0)
    orient = batch.var(frame, "Orientation", _frame_value(s.pose).Orientation,
                       ua.VariantType.ExtensionObject, O.ThreeDOrientation,
                       O.ThreeDOrientationType, name_ns=0, description=ORIENTATION_ORDER)
    batch.prop(coords, "LengthUnit", UNITS["mm"], O.EUInformation)  # CartesianCoordinatesType
    batch.prop(orient, "AngleUnit", UNITS["deg"], O.EUInformation)  # OrientationType
    ids = {"frame": frame, "coords": coords, "orient": orient}
    for k in "XYZ":
        ids[k] = batch.var(coords, k, 0.0, D, O.Double, name_ns=0)
    for k in "ABC":
        ids[k] = batch.var(orient, k, 0.0, D, O.Double, name_ns=0)
    for name, value, variant, dt in (
            ("Name", "", S, O.String), ("Kind", "", S, O.String), ("MassKg", 0.0, D, O.Double),
            ("Version", 0, ua.VariantType.UInt64, O.UInt64), ("Method", "", S, O.String),
            ("ErrorRmsMm", 0.0, D, O.Double), ("ErrorMaxMm", 0.0, D, O.Double),
            ("UpdatedAt", "", S, O.String)):
        ids[name] = batch.var(obj, name, value, variant, dt)
    return ids


def _slot_nodes(server: Server, ids: dict[str, ua.NodeId]) -> SlotNodes:
    n = server.get_node
    return SlotNodes(
        name=n(ids["Name"]), kind=n(ids["Kind"]), frame=n(ids["frame"]),
        coords=n(ids["coords"]), orient=n(ids["orient"]),
        xyz=tuple(n(ids[k]) for k in "XYZ"), abc=tuple(n(ids[k]) for k in "ABC"),  # type: ignore[arg-type]
        mass=n(ids["MassKg"]), version=n(ids["Version"]), method=n(ids["Method"]),
        error_rms=n(ids["ErrorRmsMm"]), error_max=n(ids["ErrorMaxMm"]),
        updated_at=n(ids["UpdatedAt"]))


def _frame_value(pose: tuple[float, ...]) -> ua.ThreeDFrame:
    a, b, c = opc_orientation(*pose[3:6])
    return ua.ThreeDFrame(
        CartesianCoordinates=ua.ThreeDCartesianCoordinates(X=pose[0], Y=pose[1], Z=pose[2]),
        Orientation=ua.ThreeDOrientation(A=a, B=b, C=c))


async def update_cell(nodes: CellNodes, old: ControllerState | None, new: ControllerState) -> int:
    """Write the values that differ between ``old`` and ``new``; returns how many were written."""
    writes: list[tuple[Node, object, ua.VariantType]] = []
    dbl, s_, i32 = ua.VariantType.Double, ua.VariantType.String, ua.VariantType.Int32
    ext = ua.VariantType.ExtensionObject
    for i, q in enumerate(new.joints_deg):
        if old is None or old.joints_deg[i] != q:
            writes.append((nodes.axes[i], q, dbl))
    if old is None or old.active_tool_no != new.active_tool_no:
        writes.append((nodes.active_tool, new.active_tool_no, i32))
    if old is None or old.current_user != new.current_user:  # Robotics: CurrentUser/Level
        writes.append((nodes.current_user, new.current_user, s_))
    if old is None or old.active_base_no != new.active_base_no:
        writes.append((nodes.active_base, new.active_base_no, i32))
    tool_old = old.slot("tool", old.active_tool_no) if old else None
    tool_new = new.slot("tool", new.active_tool_no)
    if old is None or tool_old != tool_new:
        mass = tool_new.mass_kg if tool_new and tool_new.mass_kg is not None else 0.0
        com = tool_new.com_mm if tool_new else (0.0, 0.0, 0.0)
        inertia = tool_new.inertia_kgm2 if tool_new else (0.0, 0.0, 0.0)
        writes.append((nodes.flange_mass, mass, dbl))
        coords = ua.ThreeDCartesianCoordinates(X=com[0], Y=com[1], Z=com[2])
        writes += [(nodes.flange_com_frame, ua.ThreeDFrame(
                        CartesianCoordinates=coords, Orientation=ua.ThreeDOrientation()), ext),
                   (nodes.flange_com_coords, coords, ext),
                   (nodes.flange_inertia_vector,
                    ua.ThreeDVector(X=inertia[0], Y=inertia[1], Z=inertia[2]), ext)]
        writes += [(n, v, dbl) for n, v in zip(nodes.flange_com, com)]
        writes += [(n, v, dbl) for n, v in zip(nodes.flange_inertia, inertia)]
    if old is None or old.sessions != new.sessions:
        writes.append((nodes.sessions, [f"{s.id} {s.method} -> {s.target}: {s.state}, "
                                        f"{s.points} touch-ups" for s in new.sessions], s_))
    for s in new.slots:
        prev = old.slot(s.table, s.number) if old else None
        if prev == s:
            continue
        sn = nodes.slots[(s.table, s.number)]
        frame = _frame_value(s.pose)
        o = frame.Orientation
        writes += [(sn.name, s.name, s_), (sn.kind, s.kind, s_),
                   (sn.frame, frame, ua.VariantType.ExtensionObject),
                   (sn.coords, frame.CartesianCoordinates, ua.VariantType.ExtensionObject),
                   (sn.orient, frame.Orientation, ua.VariantType.ExtensionObject),
                   (sn.mass, s.mass_kg if s.mass_kg is not None else 0.0, dbl),
                   (sn.version, s.version, ua.VariantType.UInt64),
                   (sn.method, s.method or "", s_),
                   (sn.error_rms, s.error_rms_mm if s.error_rms_mm is not None else 0.0, dbl),
                   (sn.error_max, s.error_max_mm if s.error_max_mm is not None else 0.0, dbl),
                   (sn.updated_at, s.updated_at, s_)]
        writes += [(n, v, dbl) for n, v in zip(sn.xyz, s.pose[:3])]
        writes += [(n, v, dbl) for n, v in zip(sn.abc, (o.A, o.B, o.C))]
    await write_many(writes)
    return len(writes)


async def event_generator(server: Server, ns: int):
    """``PendantEventType`` (a BaseEventType) raised by the Server object for every outbox
    event: Kind, Controller, Payload (the JSON the webhooks carry), EventRecordId."""
    etype = await server.create_custom_event_type(
        ns, "PendantEventType", ua.ObjectIds.BaseEventType,
        [("Kind", ua.VariantType.String), ("Controller", ua.VariantType.String),
         ("Payload", ua.VariantType.String), ("EventRecordId", ua.VariantType.Int64)])
    return await server.get_event_generator(etype, server.nodes.server)


async def raise_event(gen, ev: EventState) -> None:
    gen.event.Kind = ev.kind
    gen.event.Controller = ev.controller or ""
    gen.event.Payload = json.dumps(ev.payload, separators=(",", ":"))
    gen.event.EventRecordId = ev.id
    gen.event.Message = ua.LocalizedText(f"{ev.kind} on {ev.controller or 'the service'}")
    gen.event.Severity = 300
    await gen.trigger()


async def add_method_node(server: Server, parent: Node, name: str, ns: int,
                          inputs: list[ua.Argument], outputs: list[ua.Argument]) -> Node:
    """A method of ``parent`` and its argument properties, every NodeId derived from the
    parent's (asyncua's ``add_method`` numbers the properties: another id after a restart);
    the caller links its callback."""
    from asyncua.common.manage_nodes import create_property

    method_id = ua.NodeId(f"{parent.nodeid.Identifier}.{name}", ns)
    attrs = ua.MethodAttributes(DisplayName=ua.LocalizedText(name), Executable=True,
                                UserExecutable=True)
    (res,) = await server.iserver.isession.add_nodes([ua.AddNodesItem(
        ParentNodeId=parent.nodeid, ReferenceTypeId=ua.NodeId(ua.ObjectIds.HasComponent),
        RequestedNewNodeId=method_id, BrowseName=ua.QualifiedName(name, ns),
        NodeClass=ua.NodeClass.Method, NodeAttributes=attrs)])
    res.StatusCode.check()
    method = server.get_node(method_id)
    for prop, args in (("InputArguments", inputs), ("OutputArguments", outputs)):
        await create_property(method, ua.NodeId(f"{method_id.Identifier}.{prop}", ns),
                              ua.QualifiedName(prop, 0), args,
                              varianttype=ua.VariantType.ExtensionObject,
                              datatype=ua.ObjectIds.Argument)
    return method
