# wrinklepipe: drives wrinkle.gdshader's weight array from region weights (Godot 4).
#
# Add this node next to the face, set `mesh` to its MeshInstance3D (whose surface `surface` uses
# a ShaderMaterial with wrinkle.gdshader), `setup_path` to wrinkle_setup.json and optionally
# `curve_path` to a curve (curves/NAME.json). Every frame the region weights (one per region,
# in the asset's region order; set them from your own code or let the curve play) are written
# into wp_w through the slot table: wp_w[slot / 4][slot % 4] = weight. With `animation_player`
# set, the curve follows that player's position, so the wrinkles play in step with the face's
# blend-shape animation.
@tool
extends Node

@export var mesh: MeshInstance3D
@export var surface := 0
@export_file("*.json") var setup_path := ""
@export_file("*.json") var curve_path := ""
@export var playing := true
@export var looping := true
@export var animation_player: AnimationPlayer
@export var weights := PackedFloat32Array()

var time := 0.0
var _slots: Array = []
var _n_vectors := 0
var _curve: Dictionary = {}


func _read_json(path: String) -> Variant:
	if path == "":
		return null
	var text := FileAccess.get_file_as_string(path)
	if text == "":
		push_error("wrinklepipe: cannot read %s" % path)
		return null
	return JSON.parse_string(text)


func _ready() -> void:
	var setup: Variant = _read_json(setup_path)
	if setup == null:
		return
	var shader: Dictionary = setup["shader"]
	_slots = shader["slots"]
	_n_vectors = int(shader["weightVectors"])
	if weights.size() != _slots.size():
		weights.resize(_slots.size())
	var used := []
	var u: Array = shader["used"]
	for g in range(int(shader["groups"])):
		used.append(Vector4(u[4 * g], u[4 * g + 1], u[4 * g + 2], u[4 * g + 3]))
	var mat := _material()
	if mat:
		mat.set_shader_parameter("wp_used", used)
	var c: Variant = _read_json(curve_path)
	if c != null:
		_curve = c


func _material() -> ShaderMaterial:
	if mesh == null:
		return null
	var m := mesh.get_active_material(surface)
	return m as ShaderMaterial


# The curve's region weights at time t (linear between keys, held before and after).
func sample(t: float) -> PackedFloat32Array:
	var times: Array = _curve["times"]
	var values: Array = _curve["values"]
	var r := int(_curve["regionCount"])
	var out := PackedFloat32Array()
	out.resize(r)
	var n := times.size()
	var lo := 0
	var hi := 0
	var a := 0.0
	if t <= times[0] or n == 1:
		lo = 0
		hi = 0
	elif t >= times[n - 1]:
		lo = n - 1
		hi = n - 1
	else:
		hi = times.bsearch(t)
		lo = hi - 1
		a = (t - times[lo]) / (times[hi] - times[lo])
	for i in range(r):
		out[i] = lerp(float(values[lo * r + i]), float(values[hi * r + i]), a)
	return out


func _process(delta: float) -> void:
	if _slots.is_empty():
		return
	if not _curve.is_empty():
		var times: Array = _curve["times"]
		var length: float = times[times.size() - 1]
		if animation_player and animation_player.is_playing():
			time = animation_player.current_animation_position
		elif playing:
			time += delta
		if looping and length > 0.0:
			time = fposmod(time, length)
		weights = sample(time)
	var vecs := []
	vecs.resize(_n_vectors)
	for i in range(_n_vectors):
		vecs[i] = Vector4.ZERO
	for r in range(_slots.size()):
		for slot in _slots[r]:
			var v: Vector4 = vecs[int(slot) >> 2]
			v[int(slot) & 3] = weights[r]
			vecs[int(slot) >> 2] = v
	var mat := _material()
	if mat:
		mat.set_shader_parameter("wp_w", vecs)
