# lipstream client for Godot 4 (docs/how-to/godot.md), JSON subprotocol: say(text) sends start
# (output.retarget: the rig preset), text and end; the server's ready, audio (all before the
# frames it drives), frames and done play the speech and move blend shapes on the audio clock.
class_name LipstreamClient
extends Node

@export var server_url := "ws://127.0.0.1:8000/v1/stream"
@export var engine := "viseme-lerp"
@export var character := "demo"
## Rig preset (output.retarget) whose control names are your mesh's blend shape names.
@export var retarget := "vrm1"
@export var fps := 60.0
@export var face: MeshInstance3D
@export var speaker: AudioStreamPlayer
## Channel name -> blend shape name, for blend shapes named otherwise than the channels.
@export var renames := {}
@export var voice := "en-us"

var _socket := WebSocketPeer.new()
var _requests := 0
var _id := ""
var _pending: Array[String] = []
var _channels := PackedStringArray()
var _shapes := PackedInt32Array()
var _frames: Array = []
var _speech := PackedByteArray()
var _sample_rate := 22050
var _fps := 60.0
var _started_usec := -1
var _close_reported := false


func _ready() -> void:
	_socket.supported_protocols = PackedStringArray(["lipstream.v1.json"])
	var failed := _socket.connect_to_url(server_url)
	if failed != OK:
		push_error("lipstream: cannot connect to %s (%s)" % [server_url, error_string(failed)])


## Speak `text`: the request goes out as soon as the connection is open.
func say(text: String) -> void:
	_pending.append(text)


func _process(_delta: float) -> void:
	_socket.poll()
	var state := _socket.get_ready_state()
	if state == WebSocketPeer.STATE_CLOSED and not _close_reported:
		var code := _socket.get_close_code()
		push_error("lipstream: connection closed (%d %s)" % [code, _socket.get_close_reason()])
		_close_reported = true
	if state != WebSocketPeer.STATE_OPEN:
		return
	while not _pending.is_empty():
		_start(_pending.pop_front())
	while _socket.get_available_packet_count() > 0:
		var message = JSON.parse_string(_socket.get_packet().get_string_from_utf8())
		if message is Dictionary:
			_receive(message)
	_show(_playback_time())


func _send(message: Dictionary) -> void:
	message["v"] = 1
	_socket.send_text(JSON.stringify(message))


func _start(text: String) -> void:
	_requests += 1
	_id = "godot-%d" % _requests
	_frames.clear()
	_speech.clear()
	_started_usec = -1
	if speaker:
		speaker.stop()
	_send({
		"type": "start", "id": _id, "engine": engine, "character": character, "fps": fps,
		"output": {"retarget": retarget},
	})
	_send({"type": "text", "id": _id, "text": text, "voice": voice})
	_send({"type": "end", "id": _id})


func _receive(message: Dictionary) -> void:
	if message["type"] == "error":
		push_error("lipstream: %s: %s" % [message["code"], message["message"]])
		if message["fatal"] and message["id"] == _id:
			_id = ""
		return
	if message["id"] != _id:
		return
	match message["type"]:
		"ready":
			_channels = PackedStringArray(message["channels"])
			_fps = float(message["fps"])
			_shapes.clear()
			for channel in _channels:
				_shapes.append(face.find_blend_shape_by_name(renames.get(channel, channel)) if face else -1)
		"audio":
			_sample_rate = int(message["sample_rate"])
			_speech.append_array(Marshalls.base64_to_raw(message["pcm16"]))
		"frames":
			var first := int(message["first_frame"])
			if _frames.size() < first + message["data"].size():
				_frames.resize(first + message["data"].size())
			for r in message["data"].size():
				_frames[first + r] = message["data"][r]
			if _started_usec == -1:
				_play()
		"done":
			_frames.resize(int(message["stats"]["frames"]))


# All of a text's speech arrives before its first frames, so it plays whole from here.
func _play() -> void:
	_started_usec = Time.get_ticks_usec()
	if speaker and not _speech.is_empty():
		var stream := AudioStreamWAV.new()
		stream.format = AudioStreamWAV.FORMAT_16_BITS
		stream.mix_rate = _sample_rate
		stream.data = _speech
		speaker.stream = stream
		speaker.play()


# The audio clock while the speech plays (Godot's "Sync the gameplay with audio"), else ticks.
func _playback_time() -> float:
	if _started_usec < 0:
		return -1.0
	if speaker and speaker.playing:
		var mixed := AudioServer.get_time_since_last_mix() - AudioServer.get_output_latency()
		return speaker.get_playback_position() + mixed
	return (Time.get_ticks_usec() - _started_usec) / 1e6


func _show(t: float) -> void:
	if t < 0.0 or _frames.is_empty() or face == null:
		return
	var index := mini(int(t * _fps), _frames.size() - 1)
	while index > 0 and _frames[index] == null:
		index -= 1
	var row = _frames[index]
	if row == null:
		return
	for k in _shapes.size():
		if _shapes[k] >= 0:
			face.set_blend_shape_value(_shapes[k], row[k])
