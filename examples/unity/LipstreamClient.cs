// lipstream client for Unity: speaks text through a lipstream server and drives a SkinnedMeshRenderer's
// blend shapes in step with the speech. Protocol: docs/reference/protocol.md, JSON subprotocol. Say():
// start (output.retarget = the rig preset), text, end; the server answers ready (channel names), audio
// (the speech, all before the frames it drives), frames (rows from first_frame on) and done.
using System;
using System.Collections.Concurrent;
using System.Collections.Generic;
using System.Net.WebSockets;
using System.Text;
using System.Threading;
using System.Threading.Tasks;
using Newtonsoft.Json;
using Newtonsoft.Json.Linq;
using UnityEngine;

public class LipstreamClient : MonoBehaviour
{
    public string serverUrl = "ws://127.0.0.1:8000/v1/stream";
    public string engine = "viseme-lerp", character = "demo", voice = "en-us";
    [Tooltip("Rig preset (output.retarget) whose control names are the mesh's blend shape names")]
    public string retarget = "vrm1";
    public float fps = 60f;
    public SkinnedMeshRenderer face;
    public AudioSource speaker;
    [Tooltip("channel=blendShape pairs, for blend shapes named otherwise than the channels")]
    public string[] renames = new string[0];

    const double LeadSeconds = 0.1;
    readonly ClientWebSocket socket = new ClientWebSocket();
    readonly CancellationTokenSource closing = new CancellationTokenSource();
    readonly ConcurrentQueue<JObject> inbox = new ConcurrentQueue<JObject>();
    readonly List<float[]> frames = new List<float[]>();
    readonly List<float> speech = new List<float>();
    Task connected;
    string id = "";
    int requests, sampleRate = 22050;
    int[] shapes = new int[0];
    double t0 = -1;

    void Awake()
    {
        socket.Options.AddSubProtocol("lipstream.v1.json");
        connected = socket.ConnectAsync(new Uri(serverUrl), closing.Token);
        Task.Run(() => Receive());
    }

    void OnDestroy() { closing.Cancel(); socket.Dispose(); }

    public async void Say(string text)
    {
        await connected;
        id = "unity-" + ++requests;
        frames.Clear(); speech.Clear(); t0 = -1;
        await Send(new { v = 1, type = "start", id, engine, character, fps, output = new { retarget } });
        await Send(new { v = 1, type = "text", id, text, voice });
        await Send(new { v = 1, type = "end", id });
    }

    Task Send(object message)
    {
        var bytes = Encoding.UTF8.GetBytes(JsonConvert.SerializeObject(message));
        return socket.SendAsync(new ArraySegment<byte>(bytes), WebSocketMessageType.Text, true, closing.Token);
    }

    async Task Receive()
    {
        var buffer = new byte[1 << 16];
        var text = new StringBuilder();
        try
        {
            await connected;
            while (socket.State == WebSocketState.Open)
            {
                var part = await socket.ReceiveAsync(new ArraySegment<byte>(buffer), closing.Token);
                if (part.MessageType == WebSocketMessageType.Close) { Debug.LogError("lipstream: closed " + part.CloseStatusDescription); return; }
                text.Append(Encoding.UTF8.GetString(buffer, 0, part.Count));
                if (!part.EndOfMessage) continue;
                inbox.Enqueue(JObject.Parse(text.ToString()));
                text.Clear();
            }
        }
        catch (Exception error) when (!closing.IsCancellationRequested) { Debug.LogError("lipstream: " + error.Message); }
    }

    void Update()
    {
        JObject message;
        while (inbox.TryDequeue(out message)) Handle(message);
        if (t0 < 0 || frames.Count == 0 || face == null) return;
        int index = Math.Min((int)Math.Floor((AudioSettings.dspTime - t0) * fps), frames.Count - 1);
        if (index < 0) return;
        for (int k = 0; k < shapes.Length; k++)
            if (shapes[k] >= 0) face.SetBlendShapeWeight(shapes[k], 100f * frames[index][k]); // Unity's weights run 0-100
    }

    void Handle(JObject message)
    {
        var type = (string)message["type"];
        if (type == "error")
        {
            Debug.LogError("lipstream: " + (string)message["code"] + ": " + (string)message["message"]);
            if ((bool)message["fatal"] && (string)message["id"] == id) id = "";
        }
        else if ((string)message["id"] != id) return; // a request given up
        else if (type == "ready")
        {
            var channels = message["channels"].ToObject<string[]>();
            fps = (float)message["fps"];
            shapes = new int[channels.Length];
            for (int k = 0; k < channels.Length; k++)
                shapes[k] = face != null ? face.sharedMesh.GetBlendShapeIndex(Rename(channels[k])) : -1;
        }
        else if (type == "audio")
        {
            sampleRate = (int)message["sample_rate"];
            var pcm = Convert.FromBase64String((string)message["pcm16"]);
            for (int i = 0; i + 1 < pcm.Length; i += 2) speech.Add((short)(pcm[i] | pcm[i + 1] << 8) / 32768f);
        }
        else if (type == "frames")
        {
            int first = (int)message["first_frame"];
            var rows = message["data"].ToObject<float[][]>(); // JSON numbers read as doubles, rounded to float32
            for (int r = 0; r < rows.Length; r++)
                if (first + r < frames.Count) frames[first + r] = rows[r]; else frames.Add(rows[r]);
            if (t0 < 0) Play();
        }
        else if (type == "done")
        {
            int count = (int)message["stats"]["frames"];
            if (frames.Count > count) frames.RemoveRange(count, frames.Count - count);
        }
    }

    // All of a text's speech arrives before its first frames, so it plays whole from here.
    void Play()
    {
        t0 = AudioSettings.dspTime + LeadSeconds;
        if (speaker == null || speech.Count == 0) return;
        speaker.clip = AudioClip.Create("lipstream speech", speech.Count, 1, sampleRate, false);
        speaker.clip.SetData(speech.ToArray(), 0);
        speaker.PlayScheduled(t0);
    }

    string Rename(string channel)
    {
        foreach (var pair in renames) if (pair.StartsWith(channel + "=")) return pair.Substring(channel.Length + 1);
        return channel;
    }
}
