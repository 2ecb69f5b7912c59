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
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from asyncua import Node, Server, ua
from asyncua.common.instantiate_util import instantiate

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
    return di, rob, ns


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


async def add_cell(server: Server, ns_ids: tuple[int, int, int], st: ControllerState) -> CellNodes:
    """Instantiate the controller's MotionDeviceSystem and its pendant frames object."""
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
    for var, text in (("Manufacturer", st.robot_name.split()[0]), ("Model", st.robot_name)):
        await _set(await _child(device, f"{di}:{var}"), ua.LocalizedText(text),
                   ua.VariantType.LocalizedText)
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
    await _identify(system, device, ctrl, load, st, ns_ids)

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
    return nodes


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


async def _identify(system: Node, device: Node, ctrl: Node, load: Node, st: ControllerState,
                    ns_ids: tuple[int, int, int]) -> None:
    """The mandatory values an emulated cell knows (the robot catalogue: maker and model;
    pendant: the software; the emulator: T1, no stop, full speed), and ``BadNotReadable`` for
    the rest (a motor's serial number, its temperature): never a Good Null."""
    from importlib.metadata import PackageNotFoundError, version

    di, rob, _ns = ns_ids
    try:
        revision = version("pendant")
    except PackageNotFoundError:
        revision = "unknown"
    maker = st.robot_name.split()[0]
    lt, s_ = ua.VariantType.LocalizedText, ua.VariantType.String
    values: list[tuple[Node, object, ua.VariantType]] = [
        (await _child(device, f"{di}:ProductCode"), st.robot_key, s_),
        (await _child(device, f"{di}:SerialNumber"), f"emulated:{st.node_key}", s_),
        (await _child(device, f"{di}:ParameterSet", f"{rob}:SpeedOverride"), 100.0,
         ua.VariantType.Double),
        (await _child(ctrl, f"{di}:Manufacturer"), ua.LocalizedText("pendant"), lt),
        (await _child(ctrl, f"{di}:Model"), ua.LocalizedText(f"emulated {maker} controller"), lt),
        (await _child(ctrl, f"{di}:ProductCode"), "pendant-emulator", s_),
        (await _child(ctrl, f"{di}:SerialNumber"), f"emulated:{st.node_key}", s_),
    ]
    software = await _child(ctrl, f"{rob}:Software", f"{rob}:pendant")
    values += [(await _child(software, f"{di}:Manufacturer"), ua.LocalizedText("pendant"), lt),
               (await _child(software, f"{di}:Model"), ua.LocalizedText("pendant"), lt),
               (await _child(software, f"{di}:SoftwareRevision"), revision, s_)]
    task = await _child(ctrl, f"{rob}:TaskControls", f"{rob}:Calibration")
    values += [(await _child(task, f"{di}:ComponentName"), ua.LocalizedText("Calibration"), lt),
               (await _child(task, f"{di}:ParameterSet", f"{rob}:TaskProgramName"),
                "calibration menus", s_),
               (await _child(task, f"{di}:ParameterSet", f"{rob}:TaskProgramLoaded"), True,
                ua.VariantType.Boolean)]
    safety = await _child(system, f"{rob}:SafetyStates", f"{rob}:SafetyState", f"{di}:ParameterSet")
    values += [(await _child(safety, f"{rob}:EmergencyStop"), False, ua.VariantType.Boolean),
               (await _child(safety, f"{rob}:ProtectiveStop"), False, ua.VariantType.Boolean),
               (await _child(safety, f"{rob}:OperationalMode"), OPERATIONAL_MODE_T1,
                ua.VariantType.Int32),
               (await _child(load, f"{rob}:Mass", "0:EngineeringUnits"), UNITS["kg"],
                ua.VariantType.ExtensionObject)]
    # the centre of mass frame's orientation: the flange's (the inertia is about its axes)
    orient = await _child(load, f"{rob}:CenterOfMass", "0:Orientation")
    values += [(orient, ua.ThreeDOrientation(), ua.VariantType.ExtensionObject)]
    values += [(await _child(orient, f"0:{k}"), 0.0, ua.VariantType.Double) for k in "ABC"]
    for i in range(len(st.joints_deg)):
        motor = await _child(device, f"{rob}:PowerTrains", f"{rob}:PT{i + 1}", f"{rob}:Motor")
        values += [(await _child(motor, f"{di}:Manufacturer"), ua.LocalizedText(maker), lt),
                   (await _child(motor, f"{di}:Model"),
                    ua.LocalizedText(f"{st.robot_name} A{i + 1} motor"), lt),
                   (await _child(motor, f"{di}:ParameterSet", f"{rob}:MotorTemperature",
                                 "0:EngineeringUnits"), UNITS["degC"],
                    ua.VariantType.ExtensionObject)]
    for node, value, variant in values:
        await _set(node, value, variant)
    await _no_good_nulls(system)


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
    for node, value, variant in writes:
        await _set(node, value, variant)
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
