// wrinklepipe: plays wrinklepipe weight curves on a material that uses WrinkleMaps.hlsl.
//
// Add to the face's GameObject, assign wrinkle_setup.json (Setup) and optionally a curve
// (curves/NAME.unity.json), and the Renderer whose material runs the Shader Graph with the
// WrinkleNormal Custom Function. Every frame the region weights (one per region, in the
// asset's region order; set them from your own code, or let the curve play) are written into
// the shader's weight array through the slot table: _WrinkleWeights[slot / 4][slot % 4] = w.
// `Sync` follows an Animator so the wrinkles play in step with the face's blend-shape clip.
using System;
using UnityEngine;

[ExecuteAlways]
public class WrinkleWeights : MonoBehaviour
{
    public TextAsset Setup;
    public TextAsset Curve;
    public Renderer Target;
    public int MaterialIndex = 0;
    public bool Play = true;
    public bool Loop = true;
    public float Time;
    public Animator Sync;
    public float[] Weights = new float[0];

    [Serializable] class ShaderBlock
    {
        public int weightVectors;
        public int groups;
        public float[] used;
        public int[] slotFlat;
        public int[] slotOffsets;
    }

    [Serializable] class SetupFile
    {
        public string[] regionNames;
        public ShaderBlock shader;
    }

    [Serializable] class CurveFile
    {
        public string name;
        public float[] times;
        public int regionCount;
        public float[] values; // times.Length x regions, row-major
    }

    SetupFile setup;
    CurveFile curve;
    Vector4[] vectors;
    Vector4[] used;
    MaterialPropertyBlock block;
    static readonly int WeightsId = Shader.PropertyToID("_WrinkleWeights");
    static readonly int UsedId = Shader.PropertyToID("_WrinkleUsed");

    void OnEnable()
    {
        setup = Setup ? JsonUtility.FromJson<SetupFile>(Setup.text) : null;
        curve = Curve ? JsonUtility.FromJson<CurveFile>(Curve.text) : null;
        if (setup == null) return;
        int r = setup.regionNames.Length;
        if (Weights.Length != r) Array.Resize(ref Weights, r);
        vectors = new Vector4[setup.shader.weightVectors];
        used = new Vector4[setup.shader.groups];
        for (int g = 0; g < used.Length; g++)
            used[g] = new Vector4(setup.shader.used[4 * g], setup.shader.used[4 * g + 1],
                                  setup.shader.used[4 * g + 2], setup.shader.used[4 * g + 3]);
        block = new MaterialPropertyBlock();
    }

    // The curve's region weights at time t (linear between keys, held before and after).
    public void Sample(float t, float[] into)
    {
        var times = curve.times;
        int n = times.Length, r = curve.regionCount;
        if (t <= times[0] || n == 1) { Array.Copy(curve.values, 0, into, 0, r); return; }
        if (t >= times[n - 1]) { Array.Copy(curve.values, (n - 1) * r, into, 0, r); return; }
        int hi = Array.BinarySearch(times, t);
        if (hi < 0) hi = ~hi;
        int lo = hi - 1;
        float a = (t - times[lo]) / (times[hi] - times[lo]);
        for (int i = 0; i < r; i++)
            into[i] = Mathf.Lerp(curve.values[lo * r + i], curve.values[hi * r + i], a);
    }

    void Update()
    {
        if (setup == null || Target == null) return;
        if (curve != null && curve.times.Length > 0)
        {
            float length = curve.times[curve.times.Length - 1];
            if (Sync != null)
            {
                var st = Sync.GetCurrentAnimatorStateInfo(0);
                Time = st.normalizedTime * st.length;
            }
            else if (Play && Application.isPlaying)
            {
                Time += UnityEngine.Time.deltaTime;
            }
            if (Loop && length > 0) Time = Mathf.Repeat(Time, length);
            Sample(Time, Weights);
        }
        Array.Clear(vectors, 0, vectors.Length);
        var flat = setup.shader.slotFlat;
        var off = setup.shader.slotOffsets;
        for (int i = 0; i < Weights.Length; i++)
        {
            for (int s = off[i]; s < off[i + 1]; s++)
            {
                int slot = flat[s];
                Vector4 v = vectors[slot >> 2];
                v[slot & 3] = Weights[i];
                vectors[slot >> 2] = v;
            }
        }
        Target.GetPropertyBlock(block, MaterialIndex);
        block.SetVectorArray(WeightsId, vectors);
        block.SetVectorArray(UsedId, used);
        Target.SetPropertyBlock(block, MaterialIndex);
    }
}
