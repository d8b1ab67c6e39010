// wrinklepipe: a GLTFLoader plugin for WRINKLEPIPE_wrinkle_maps (animated facial wrinkle maps).
//
//   import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
//   import { WrinkleMapsPlugin } from './WrinkleMapsPlugin.js';
//   const loader = new GLTFLoader();
//   loader.register( ( parser ) => new WrinkleMapsPlugin( parser, { renderer } ) );
//   const gltf = await loader.loadAsync( 'head.gltf' );
//   const mixer = new AnimationMixer( gltf.scene );
//   mixer.clipAction( gltf.animations[ 0 ] ).play();   // morphs and wrinkle weights together
//   gltf.userData.wrinkles[ 0 ].weights[ 3 ] = 0.8;      // or drive region weights yourself
//
// For every material with the extension the plugin loads the wrinkle state and mask textures,
// copies them into two texture arrays on the GPU (exact for 8-bit texels), and patches the
// material (onBeforeCompile) so its tangent-space normal is the wrinkle model of
// wrinklepipe/model.py: the base normal map (the material's normalMap) plus the states, weighted
// per texel by masks x region weights under the asset's policy and encoding. The GLSL is
// generated from wrinklepipe's shader template (wrinkle_core.js). The region weights live in
// `wrinkles[i].weights` (a Float32Array, one per region); the KHR_animation_pointer channels that
// animate /materials/N/extensions/WRINKLEPIPE_wrinkle_maps/weights become NumberKeyframeTracks
// on that array, added to the same AnimationClip as the glTF animation's morph tracks, so one
// AnimationMixer plays the face and its wrinkles in step.
//
// States with a colour map (colorTexture) blend it over the material's base colour (three's
// diffuseColor: its map, sRGB, times its color; with exact, the map's level 0 times the color)
// with the same activations, in linear light; the colour maps are sampled as sRGB textures
// (decoded before filtering).
//
// Options: renderer (required: the arrays are built on the GPU); debug: 0 normal shading,
// 1 output the tangent-space normal (gl_FragColor = vec4(N, 1)), 2 output (uv, sum |a_k|, 1),
// 3 output (view-space position, sum |a_k|), 4 the blended base colour (linear, sum |a_k|);
// exact: sample level 0 without mipmaps (what wrinklepipe's numpy reference does).

import {
	AnimationClip,
	InterpolateDiscrete,
	InterpolateLinear,
	Interpolant,
	LinearFilter,
	LinearMipmapLinearFilter,
	Mesh,
	NoColorSpace,
	NumberKeyframeTrack,
	Object3D,
	OrthographicCamera,
	PlaneGeometry,
	RGBAFormat,
	SRGBColorSpace,
	ShaderChunk,
	ShaderMaterial,
	UnsignedByteType,
	WebGLArrayRenderTarget,
	ClampToEdgeWrapping,
} from 'three';
import { WRINKLE_CORE, WRINKLE_CORE_COLOR, WRINKLE_FUNCTIONS } from './wrinkle_core.js';
import { regionColors, weightVectors, wrinkleSetup } from './wrinkle_setup.js';

export const EXTENSION = 'WRINKLEPIPE_wrinkle_maps';
const POINTER = /^\/materials\/(\d+)\/extensions\/WRINKLEPIPE_wrinkle_maps\/weights$/;

// The statements that replace three's `vec3 mapN = texture2D( normalMap, vNormalMapUv )...`.
const BODY_HEAD = `
	vec2 wp_uv = vNormalMapUv;
	vec2 wp_dx = dFdx( wp_uv );
	vec2 wp_dy = dFdy( wp_uv );
#if WP_EXACT
#define WP_BASE() textureLod( normalMap, wp_uv, 0.0 )
#define WP_STATE(k) textureLod( wpStates, vec3( wp_uv, float( k ) ), 0.0 )
#define WP_MASK(l) textureLod( wpMasks, vec3( wp_uv, float( l ) ), 0.0 )
#else
#define WP_BASE() textureGrad( normalMap, wp_uv, wp_dx, wp_dy )
#define WP_STATE(k) textureGrad( wpStates, vec3( wp_uv, float( k ) ), wp_dx, wp_dy )
#define WP_MASK(l) textureGrad( wpMasks, vec3( wp_uv, float( l ) ), wp_dx, wp_dy )
#endif
#define WP_W(i) wpW[ i ]
#define WP_USED(g) wpUsed[ g ]
#define WP_REGION_COLOR(i) wpColors[ i ].rgb
`;

const BODY = BODY_HEAD + `${ WRINKLE_CORE }
	vec3 mapN = wp_n;
	diffuseColor.rgb = mix( diffuseColor.rgb, wp_regions, wpShowRegions * 0.7 );
`;

// With colour states: the colour maps (sRGB textures wpColorMap0..N-1) over diffuseColor.
function colorBody( nColors ) {

	const sample = ( c ) => `textureLod( wpColorMap${ c }, wp_uv, 0.0 )`;
	const grad = ( c ) => `textureGrad( wpColorMap${ c }, wp_uv, wp_dx, wp_dy )`;
	const chain = ( tap ) => {

		let s = tap( nColors - 1 );
		for ( let c = nColors - 2; c >= 0; c -- ) s = `( (c) == ${ c } ? ${ tap( c ) } : ${ s } )`;
		return s;

	};

	return BODY_HEAD + `
#if WP_EXACT && defined( USE_MAP )
#define WP_COLOR_BASE() ( textureLod( map, vMapUv, 0.0 ).rgb * diffuse )
#else
#define WP_COLOR_BASE() diffuseColor.rgb
#endif
#if WP_EXACT
#define WP_COLOR(c) ${ chain( sample ) }.rgb
#else
#define WP_COLOR(c) ${ chain( grad ) }.rgb
#endif
${ WRINKLE_CORE_COLOR }
	vec3 mapN = wp_n;
	diffuseColor.rgb = wp_color;
	diffuseColor.rgb = mix( diffuseColor.rgb, wp_regions, wpShowRegions * 0.7 );
`;

}

const DECLARATIONS = `
uniform highp sampler2DArray wpStates;
uniform highp sampler2DArray wpMasks;
uniform vec4 wpW[ WP_NUM_WEIGHTS ];
uniform vec4 wpUsed[ WP_NUM_GROUPS ];
uniform vec4 wpColors[ WP_NUM_GROUPS * 4 ];
uniform float wpShowRegions;
${ WRINKLE_FUNCTIONS }
`;

const DEBUG_OUTPUT = `
#if WP_DEBUG == 1
	gl_FragColor = vec4( wp_n, 1.0 );
#elif WP_DEBUG == 2
	gl_FragColor = vec4( wp_uv, wp_activity, 1.0 );
#elif WP_DEBUG == 3
	gl_FragColor = vec4( - vViewPosition, wp_activity );
#elif WP_DEBUG == 4 && defined( WP_NUM_COLORS )
	gl_FragColor = vec4( wp_color, wp_activity );
#endif
`;

const MAP_LINE = 'vec3 mapN = texture2D( normalMap, vNormalMapUv ).xyz * 2.0 - 1.0;';

export class WrinkleMapsPlugin {

	constructor( parser, options = {} ) {

		this.name = EXTENSION;
		this.parser = parser;
		this.renderer = options.renderer;
		this.debug = options.debug || 0;
		this.exact = options.exact ? 1 : 0;

	}

	async afterRoot( result ) {

		const parser = this.parser;
		const json = parser.json;
		const materials = json.materials || [];
		const wrinkles = [];
		const byMaterial = new Map();
		for ( let i = 0; i < materials.length; i ++ ) {

			const ext = materials[ i ].extensions && materials[ i ].extensions[ EXTENSION ];
			if ( ! ext ) continue;
			if ( ! this.renderer ) throw new Error( `${ EXTENSION }: the plugin needs { renderer } to build its texture arrays` );
			const w = await this._material( i, ext, result );
			wrinkles.push( w );
			byMaterial.set( i, w );

		}

		result.userData.wrinkles = wrinkles;
		if ( wrinkles.length ) await this._animations( result, byMaterial );

	}

	async _material( index, ext, result ) {

		const parser = this.parser;
		const setup = wrinkleSetup( ext, { baseLayout: 'rgb', stateLayout: 'rgb', stateBits: 8 } );
		if ( setup.problems.length ) {

			throw new Error( `${ EXTENSION } (material ${ index }): cannot build the wrinkle shader: ${ setup.problems.join( '; ' ) }` );

		}

		const tex = ( info ) => parser.getDependency( 'texture', info.index );
		const stateTex = await Promise.all( ext.states.map( ( s ) => tex( s.texture ) ) );
		const maskTex = await Promise.all( ext.masks.textures.map( tex ) );
		const states = this._array( stateTex );
		const masks = this._array( maskTex );
		// colour maps: sRGB textures (a clone of each, so a texture the scene also uses keeps
		// its own colour space)
		const colorTex = ( await Promise.all( setup.colorStates.map( ( k ) => tex( ext.states[ k ].colorTexture ) ) ) )
			.map( ( t ) => {

				const c = t.clone();
				c.colorSpace = SRGBColorSpace;
				c.needsUpdate = true;
				return c;

			} );
		const holder = new Object3D();
		holder.name = `WRINKLEPIPE_weights_${ index }`;
		holder.wrinkleWeights = new Float32Array( setup.regions.length );
		( ext.weights || [] ).forEach( ( v, r ) => {

			if ( r < holder.wrinkleWeights.length ) holder.wrinkleWeights[ r ] = v;

		} );
		result.scene.add( holder );
		const uniforms = {
			wpStates: { value: states.texture },
			wpMasks: { value: masks.texture },
			wpW: { value: new Float32Array( setup.nWeightVectors * 4 ) },
			wpUsed: { value: setup.used },
			wpColors: { value: regionColors( setup ) },
			wpShowRegions: { value: 0 },
		};
		colorTex.forEach( ( t, c ) => {

			uniforms[ `wpColorMap${ c }` ] = { value: t };

		} );
		const wrinkle = {
			material: index,
			extension: ext,
			setup,
			holder,
			weights: holder.wrinkleWeights,
			uniforms,
			arrays: [ states, masks ],
			materials: [],
			showRegions( on ) {

				uniforms.wpShowRegions.value = on ? 1 : 0;

			},
			// debug: 0 shading, 1 tangent-space normal, 2 (uv, activity); exact: level 0, no mips
			setDebug( debug, exact ) {

				for ( const m of this.materials ) {

					if ( m.defines.WP_DEBUG === debug && m.defines.WP_EXACT === ( exact ? 1 : 0 ) ) continue;
					m.defines.WP_DEBUG = debug;
					m.defines.WP_EXACT = exact ? 1 : 0;
					m.needsUpdate = true;

				}

			},
		};
		const plugin = this;
		result.scene.traverse( ( obj ) => {

			if ( ! obj.isMesh ) return;
			const list = Array.isArray( obj.material ) ? obj.material : [ obj.material ];
			for ( const m of list ) {

				const assoc = parser.associations.get( m );
				if ( ! assoc || assoc.materials !== index || wrinkle.materials.includes( m ) ) continue;
				plugin._patch( m, wrinkle );
				wrinkle.materials.push( m );

			}

		} );
		return wrinkle;

	}

	// Copy 2D textures (one per layer) into a texture array on the GPU, texel for texel.
	_array( textures ) {

		const renderer = this.renderer;
		const img = textures[ 0 ].image;
		const w = img.width, h = img.height;
		for ( const t of textures ) {

			if ( t.image.width !== w || t.image.height !== h ) {

				throw new Error( `${ EXTENSION }: wrinkle textures of one kind must share a size (${ w }x${ h } vs ${ t.image.width }x${ t.image.height })` );

			}

		}

		const target = new WebGLArrayRenderTarget( w, h, textures.length, {
			format: RGBAFormat, type: UnsignedByteType, depthBuffer: false,
			minFilter: LinearMipmapLinearFilter, magFilter: LinearFilter, generateMipmaps: true,
		} );
		target.texture.colorSpace = NoColorSpace;
		target.texture.wrapS = target.texture.wrapT = ClampToEdgeWrapping;
		const copy = new ShaderMaterial( {
			glslVersion: '300 es',
			uniforms: { src: { value: null } },
			vertexShader: 'void main() { gl_Position = vec4( position.xy * 2.0, 0.0, 1.0 ); }',
			fragmentShader: 'uniform sampler2D src;\nout vec4 color;\n' +
				'void main() { color = texelFetch( src, ivec2( gl_FragCoord.xy ), 0 ); }',
			depthTest: false, depthWrite: false,
		} );
		const quad = new Mesh( new PlaneGeometry( 1, 1 ), copy );
		const camera = new OrthographicCamera();
		const previous = renderer.getRenderTarget();
		const autoClear = renderer.autoClear;
		renderer.autoClear = false;
		textures.forEach( ( t, layer ) => {

			t.colorSpace = NoColorSpace;
			copy.uniforms.src.value = t;
			renderer.setRenderTarget( target, layer );
			renderer.render( quad, camera );

		} );
		renderer.setRenderTarget( previous );
		renderer.autoClear = autoClear;
		copy.dispose();
		quad.geometry.dispose();
		return target;

	}

	_patch( material, wrinkle ) {

		if ( ! material.normalMap ) {

			throw new Error( `${ EXTENSION }: material '${ material.name }' has no normalTexture (the base normal map)` );

		}

		const { setup, uniforms } = wrinkle;
		material.defines = Object.assign( material.defines || {}, setup.defines, { WP_DEBUG: this.debug, WP_EXACT: this.exact } );
		material.onBeforeCompile = ( shader ) => {

			Object.assign( shader.uniforms, uniforms );
			const chunk = ShaderChunk.normal_fragment_maps;
			if ( ! chunk.includes( MAP_LINE ) ) throw new Error( `${ EXTENSION }: this three.js version's normal_fragment_maps chunk is not the one the plugin patches` );
			const nColors = setup.colorStates.length;
			const declarations = DECLARATIONS + setup.colorStates.map( ( k, c ) => `uniform sampler2D wpColorMap${ c };\n` ).join( '' );
			const body = nColors ? colorBody( nColors ) : BODY;
			shader.fragmentShader = shader.fragmentShader
				.replace( '#include <common>', '#include <common>\n' + declarations )
				.replace( '#include <normal_fragment_maps>', chunk.replace( MAP_LINE, body ) )
				.replace( '#include <dithering_fragment>', '#include <dithering_fragment>\n' + DEBUG_OUTPUT );

		};

		material.customProgramCacheKey = () => `wrinklepipe:${ JSON.stringify( material.defines ) }`;
		material.onBeforeRender = () => weightVectors( setup, wrinkle.weights, uniforms.wpW.value );
		material.needsUpdate = true;

	}

	// KHR_animation_pointer channels on .../WRINKLEPIPE_wrinkle_maps/weights -> keyframe tracks
	// on the weights array, added to the clip GLTFLoader made for the same glTF animation.
	async _animations( result, byMaterial ) {

		const parser = this.parser;
		const animations = parser.json.animations || [];
		for ( let a = 0; a < animations.length; a ++ ) {

			const anim = animations[ a ];
			const tracks = [];
			for ( const ch of anim.channels || [] ) {

				const ptr = ch.target && ch.target.extensions && ch.target.extensions.KHR_animation_pointer;
				const m = ptr && POINTER.exec( ptr.pointer );
				if ( ! m || ! byMaterial.has( Number( m[ 1 ] ) ) ) continue;
				const wrinkle = byMaterial.get( Number( m[ 1 ] ) );
				const sampler = anim.samplers[ ch.sampler ];
				const [ input, output ] = await Promise.all( [
					parser.getDependency( 'accessor', sampler.input ),
					parser.getDependency( 'accessor', sampler.output ),
				] );
				tracks.push( ...weightTracks( wrinkle.holder, input.array, output.array, sampler.interpolation || 'LINEAR', wrinkle.weights.length ) );

			}

			if ( ! tracks.length ) continue;
			let clip = result.animations[ a ];
			if ( ! clip ) {

				clip = new AnimationClip( anim.name || `animation_${ a }`, - 1, [] );
				result.animations[ a ] = clip;

			}

			clip.tracks.push( ...tracks );
			clip.resetDuration();

		}

	}

}

// One NumberKeyframeTrack per region: `<holder uuid>.wrinkleWeights[r]`.
export function weightTracks( holder, times, values, interpolation, nRegions ) {

	const nKeys = times.length;
	const cubic = interpolation === 'CUBICSPLINE';
	const stride = nRegions * ( cubic ? 3 : 1 );
	const tracks = [];
	for ( let r = 0; r < nRegions; r ++ ) {

		const v = new Float32Array( nKeys * ( cubic ? 3 : 1 ) );
		for ( let k = 0; k < nKeys; k ++ ) {

			if ( cubic ) {

				for ( let j = 0; j < 3; j ++ ) v[ k * 3 + j ] = values[ k * stride + j * nRegions + r ];

			} else {

				v[ k ] = values[ k * stride + r ];

			}

		}

		const track = new NumberKeyframeTrack( `${ holder.uuid }.wrinkleWeights[${ r }]`, Float32Array.from( times ), v );
		if ( interpolation === 'STEP' ) track.setInterpolation( InterpolateDiscrete );
		else if ( cubic ) track.createInterpolant = function ( result ) {

			return new CubicSplineInterpolant( this.times, this.values, 1, result );

		};
		else track.setInterpolation( InterpolateLinear );
		tracks.push( track );

	}

	return tracks;

}

// glTF CUBICSPLINE (Hermite with in/out tangents; values stored [in, value, out] per key).
class CubicSplineInterpolant extends Interpolant {

	copySampleValue_( index ) {

		const out = this.resultBuffer;
		out[ 0 ] = this.sampleValues[ index * 3 + 1 ];
		return out;

	}

	interpolate_( i1, t0, t, t1 ) {

		const out = this.resultBuffer, v = this.sampleValues;
		const dt = t1 - t0, p = ( t - t0 ) / dt, pp = p * p, ppp = pp * p;
		const p0 = v[ ( i1 - 1 ) * 3 + 1 ], m0 = v[ ( i1 - 1 ) * 3 + 2 ] * dt;
		const p1 = v[ i1 * 3 + 1 ], m1 = v[ i1 * 3 ] * dt;
		out[ 0 ] = ( 2 * ppp - 3 * pp + 1 ) * p0 + ( ppp - 2 * pp + p ) * m0 + ( - 2 * ppp + 3 * pp ) * p1 + ( ppp - pp ) * m1;
		return out;

	}

}
