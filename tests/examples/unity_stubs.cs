// The Unity API that examples/unity/LipstreamClient.cs uses, declared with Unity's signatures
// (docs.unity3d.com ScriptReference) and no behaviour: enough for a compiler to check the client.
namespace UnityEngine
{
    public class Object
    {
        public static implicit operator bool(Object exists) { return exists != null; }
    }
    public class Component : Object { }
    public class Behaviour : Component { }
    public class MonoBehaviour : Behaviour { }
    public class Mesh : Object
    {
        public int GetBlendShapeIndex(string blendShapeName) { return -1; }
    }
    public class SkinnedMeshRenderer : Component
    {
        public Mesh sharedMesh { get; set; }
        public void SetBlendShapeWeight(int index, float value) { }
    }
    public class AudioClip : Object
    {
        public static AudioClip Create(string name, int lengthSamples, int channels, int frequency, bool stream) { return null; }
        public bool SetData(float[] data, int offsetSamples) { return true; }
    }
    public class AudioSource : Behaviour
    {
        public AudioClip clip { get; set; }
        public void PlayScheduled(double time) { }
    }
    public sealed class AudioSettings
    {
        public static double dspTime { get { return 0.0; } }
    }
    public static class Debug
    {
        public static void LogError(object message) { }
    }
    [System.AttributeUsage(System.AttributeTargets.Field)]
    public class TooltipAttribute : System.Attribute
    {
        public TooltipAttribute(string tooltip) { }
    }
}
