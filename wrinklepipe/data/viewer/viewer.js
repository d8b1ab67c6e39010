// wrinklepipe view: the artist's preview of a converted character (three.js + WrinkleMapsPlugin).
// Expression sliders set the region weights (sum of expression x its table row), the timeline
// plays the glTF animations (morph targets and wrinkle weights in one AnimationMixer), the
// overlay colours each region's mask. `window.wrinklepipe` is the page's scripting interface
// (the tests use it): load(url, { plugin }), setWeights(w), renderDebug(mode, w),
// renderDebugSets(mode, [w, ...]), renderColor(w),
// focusWrinkles(), sampleWeights(clip, t).

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { RoomEnvironment } from 'three/addons/environments/RoomEnvironment.js';
import { WrinkleMapsPlugin } from '/plugin/WrinkleMapsPlugin.js';

const $ = ( id ) => document.getElementById( id );
// ?still: render on demand only (no animation loop, no environment map): for scripted use
const still = new URLSearchParams( location.search ).has( 'still' );
const canvas = $( 'view' );
const renderer = new THREE.WebGLRenderer( { canvas, antialias: true, preserveDrawingBuffer: true } );
renderer.setPixelRatio( Math.min( window.devicePixelRatio, 2 ) );
const scene = new THREE.Scene();
scene.background = new THREE.Color( 0x1b1d21 );
if ( ! still ) scene.environment = new THREE.PMREMGenerator( renderer ).fromScene( new RoomEnvironment(), 0.04 ).texture;
const key = new THREE.DirectionalLight( 0xffffff, 1.6 );
key.position.set( - 1.5, 2.0, 2.5 );
scene.add( key );
const camera = new THREE.PerspectiveCamera( 30, 1, 0.01, 100 );
const controls = new OrbitControls( camera, canvas );
const clock = new THREE.Clock();

const state = { gltf: null, wrinkles: [], mixer: null, action: null, playing: false, sliders: [] };

function resize() {

	const w = canvas.clientWidth, h = canvas.clientHeight;
	renderer.setSize( w, h, false );
	camera.aspect = w / Math.max( h, 1 );
	camera.updateProjectionMatrix();

}

function frame( object ) {

	const box = new THREE.Box3().setFromObject( object );
	const size = box.getSize( new THREE.Vector3() ), centre = box.getCenter( new THREE.Vector3() );
	const r = Math.max( size.x, size.y ) * 0.5 / Math.tan( THREE.MathUtils.degToRad( camera.fov * 0.5 ) );
	camera.up.set( 0, 1, 0 );
	camera.position.set( centre.x, centre.y, box.max.z + r * 1.1 );
	camera.near = r / 100;
	camera.far = r * 10 + size.z * 2;
	camera.updateProjectionMatrix();
	controls.target.copy( centre );
	controls.update();

}

// Load a glTF into the scene (replacing the last one); `plugin: false` loads it with the plain
// GLTFLoader (no wrinkles), to compare against; `keepCamera: true` keeps the camera as it is.
async function load( url, { plugin = true, keepCamera = false } = {} ) {

	if ( state.gltf ) {

		scene.remove( state.gltf.scene );
		state.mixer && state.mixer.stopAllAction();

	}

	const loader = new GLTFLoader();
	if ( plugin ) loader.register( ( parser ) => new WrinkleMapsPlugin( parser, { renderer } ) );
	const gltf = await loader.loadAsync( url );
	state.gltf = gltf;
	state.wrinkles = gltf.userData.wrinkles || [];
	scene.add( gltf.scene );
	resize();
	if ( ! keepCamera ) frame( gltf.scene );
	state.mixer = new THREE.AnimationMixer( gltf.scene );
	state.action = null;
	buildPanel( gltf );
	$( 'status' ).textContent = state.wrinkles.length
		? `${ state.wrinkles[ 0 ].setup.regions.length } regions, ${ state.wrinkles[ 0 ].setup.states.length } states, ${ state.wrinkles[ 0 ].extension.encoding } / ${ state.wrinkles[ 0 ].extension.policy }`
		: 'no WRINKLEPIPE_wrinkle_maps material';
	return { wrinkles: state.wrinkles.length, animations: gltf.animations.map( ( a ) => ( { name: a.name, duration: a.duration, tracks: a.tracks.length } ) ) };

}

function expressions() {

	const w = state.wrinkles[ 0 ];
	if ( ! w ) return [];
	const ex = w.extension.expressions || [];
	return Array.isArray( ex ) ? ex : Object.entries( ex ).map( ( [ name, weights ] ) => ( { name, weights } ) );

}

function buildPanel( gltf ) {

	$( 'title' ).textContent = gltf.parser.json.asset && gltf.parser.json.asset.extras && gltf.parser.json.asset.extras.name || 'wrinklepipe';
	const box = $( 'sliders' );
	box.textContent = '';
	state.sliders = expressions().map( ( ex ) => {

		const row = document.createElement( 'div' );
		row.className = 'slider';
		const label = document.createElement( 'span' );
		label.textContent = ex.name;
		const input = Object.assign( document.createElement( 'input' ), { type: 'range', min: 0, max: 1, step: 0.01, value: 0 } );
		const value = document.createElement( 'span' );
		value.textContent = '0.00';
		input.addEventListener( 'input', () => {

			value.textContent = Number( input.value ).toFixed( 2 );
			pause();
			applySliders();

		} );
		row.append( label, input, value );
		box.append( row );
		return { ex, input, value };

	} );
	const select = $( 'clip' );
	select.textContent = '';
	gltf.animations.forEach( ( a, i ) => select.append( new Option( `${ a.name || 'animation ' + i } (${ a.duration.toFixed( 2 ) } s)`, i ) ) );
	// the clip is chosen, not yet applied: the character stays in its rest pose until the
	// timeline plays or is scrubbed
	const chosen = defaultClip( gltf.animations );
	select.value = String( chosen );
	$( 'time' ).max = gltf.animations.length ? gltf.animations[ chosen ].duration : 1;
	$( 'time' ).value = 0;
	showTime( 0 );

}

// The clip the timeline opens on: ?clip=NAME (wrinklepipe view --clip), else the first clip
// that animates the wrinkle weights (convert's weight curve), else the first.
function defaultClip( animations ) {

	const named = new URLSearchParams( location.search ).get( 'clip' );
	if ( named !== null ) {

		const i = animations.findIndex( ( a ) => a.name === named );
		if ( i >= 0 ) return i;

	}

	const wrinkle = animations.findIndex( ( a ) => a.tracks.some( ( t ) => t.name.includes( '.wrinkleWeights[' ) ) );
	return wrinkle >= 0 ? wrinkle : 0;

}

function showTime( t ) {

	$( 'clock' ).textContent = `${ t.toFixed( 2 ) } s`;

}

function applySliders() {

	for ( const w of state.wrinkles ) {

		w.weights.fill( 0 );
		for ( const s of state.sliders ) {

			const a = Number( s.input.value );
			if ( ! a ) continue;
			const row = s.ex.weights;
			w.setup.regions.forEach( ( name, r ) => {

				w.weights[ r ] += a * ( Array.isArray( row ) ? row[ r ] : ( row[ name ] || 0 ) );

			} );

		}

	}

}

function setWeights( weights ) {

	for ( const w of state.wrinkles ) w.weights.set( weights );

}

function clipAction() {

	const i = Number( $( 'clip' ).value || 0 );
	const clip = state.gltf && state.gltf.animations[ i ];
	if ( ! clip ) return null;
	if ( ! state.action || state.action.getClip() !== clip ) {

		state.mixer.stopAllAction();
		state.action = state.mixer.clipAction( clip );
		state.action.play();
		$( 'time' ).max = clip.duration;

	}

	return state.action;

}

function pause() {

	state.playing = false;
	$( 'play' ).textContent = 'play';

}

$( 'play' ).addEventListener( 'click', () => {

	if ( ! clipAction() ) return;
	state.playing = ! state.playing;
	$( 'play' ).textContent = state.playing ? 'pause' : 'play';

} );
$( 'time' ).addEventListener( 'input', () => {

	if ( ! clipAction() ) return;
	pause();
	const t = Number( $( 'time' ).value );
	state.mixer.setTime( t );
	showTime( t );

} );
$( 'clip' ).addEventListener( 'change', () => {

	pause();
	if ( clipAction() ) state.mixer.setTime( 0 );
	$( 'time' ).value = 0;
	showTime( 0 );

} );
$( 'neutral' ).addEventListener( 'click', () => {

	for ( const s of state.sliders ) {

		s.input.value = 0;
		s.value.textContent = '0.00';

	}

	applySliders();

} );
$( 'focus' ).addEventListener( 'click', () => focusWrinkles() );
$( 'regions' ).addEventListener( 'change', () => state.wrinkles.forEach( ( w ) => w.showRegions( $( 'regions' ).checked ) ) );
$( 'debug' ).addEventListener( 'change', () => state.wrinkles.forEach( ( w ) => w.setDebug( Number( $( 'debug' ).value ), false ) ) );
window.addEventListener( 'resize', resize );

function animate() {

	const dt = clock.getDelta();
	if ( state.playing && state.mixer ) {

		state.mixer.update( dt );
		const t = state.action ? state.action.time : 0;
		$( 'time' ).value = t;
		showTime( t );

	}

	renderer.render( scene, camera );

}

if ( ! still ) renderer.setAnimationLoop( animate );

// ---------------------------------------------------------------------------------------------
// scripting interface (tests): exact debug renders read back as float32

function toBase64( array ) {

	const bytes = new Uint8Array( array.buffer, array.byteOffset, array.byteLength );
	let s = '';
	for ( let i = 0; i < bytes.length; i += 0x8000 ) s += String.fromCharCode.apply( null, bytes.subarray( i, i + 0x8000 ) );
	return btoa( s );

}

// In debug renders every material without wrinkles writes 0 (it still occludes): what is read
// back is the wrinkled material's output only. Skinned and morphed meshes keep deforming.
const blank = new THREE.MeshBasicMaterial();
blank.onBeforeCompile = ( shader ) => {

	shader.fragmentShader = shader.fragmentShader.replace( '#include <dithering_fragment>', 'gl_FragColor = vec4( 0.0 );' );

};

function swapOthers( on ) {

	const wrinkled = new Set( state.wrinkles.flatMap( ( w ) => w.materials ) );
	state.gltf.scene.traverse( ( o ) => {

		if ( ! o.isMesh ) return;
		if ( on ) {

			const list = Array.isArray( o.material ) ? o.material : [ o.material ];
			if ( list.some( ( m ) => wrinkled.has( m ) ) ) return;
			o.userData.wpMaterial = o.material;
			o.material = Array.isArray( o.material ) ? o.material.map( () => blank ) : blank;

		} else if ( o.userData.wpMaterial ) {

			o.material = o.userData.wpMaterial;
			delete o.userData.wpMaterial;

		}

	} );

}

// Render targets by size and kind, kept between calls (making one per render cost more than
// the render itself in SwiftShader); every render clears colour and depth first.
const targets = new Map();

function renderTarget( size, float ) {

	const key = `${ size }:${ float }`;
	if ( ! targets.has( key ) ) {

		const options = float ? { type: THREE.FloatType, format: THREE.RGBAFormat, depthBuffer: true } : { depthBuffer: true };
		targets.set( key, new THREE.WebGLRenderTarget( size, size, options ) );

	}

	return targets.get( key );

}

// Render one frame with the materials in debug `mode` (1 normal, 2 uv + activity, 3 view-space
// position + activity), level-0 sampling, region weights `weights`, into `out` (float32,
// `size` x `size` x 4); materials without wrinkles write 0.
function debugPixels( mode, weights, size, out ) {

	if ( ! still ) renderer.setAnimationLoop( null );
	const target = renderTarget( size, true );
	for ( const w of state.wrinkles ) w.setDebug( mode, true );
	if ( weights ) setWeights( weights );
	const aspect = camera.aspect;
	camera.aspect = 1;
	camera.updateProjectionMatrix();
	const background = scene.background;
	scene.background = null;
	renderer.setRenderTarget( target );
	renderer.setClearColor( 0x000000, 0 );
	renderer.clear();
	swapOthers( true );
	renderer.render( scene, camera );
	swapOthers( false );
	renderer.readRenderTargetPixels( target, 0, 0, size, size, out );
	renderer.setRenderTarget( null );
	scene.background = background;
	camera.aspect = aspect;
	camera.updateProjectionMatrix();
	if ( ! still ) {

		for ( const w of state.wrinkles ) w.setDebug( 0, false );
		renderer.setAnimationLoop( animate );

	}

	return out;

}

// One debug render (see debugPixels), read back as base64 float32.
function renderDebug( mode, weights, size = 256 ) {

	return { size, data: toBase64( debugPixels( mode, weights, size, new Float32Array( size * size * 4 ) ) ) };

}

// One debug render per weight set in `weightSets`, the images one after another in `data`
// (`count` of them): a single call for the several weight sets a test renders per asset.
function renderDebugSets( mode, weightSets, size = 256 ) {

	const n = size * size * 4;
	const out = new Float32Array( n * weightSets.length );
	weightSets.forEach( ( w, i ) => debugPixels( mode, w, size, out.subarray( i * n, ( i + 1 ) * n ) ) );
	return { size, count: weightSets.length, data: toBase64( out ) };

}

// Render one frame as the artist sees it (lit, materials as loaded, mip-mapped) at region
// weights `weights` into an 8-bit RGBA target of `size` x `size` (square, as renderDebug).
function renderColor( weights, size = 256 ) {

	if ( ! still ) renderer.setAnimationLoop( null );
	const target = renderTarget( size, false );
	for ( const w of state.wrinkles ) w.setDebug( 0, false );
	if ( weights ) setWeights( weights );
	const aspect = camera.aspect;
	camera.aspect = 1;
	camera.updateProjectionMatrix();
	renderer.setRenderTarget( target );
	renderer.clear();
	renderer.render( scene, camera );
	const out = new Uint8Array( size * size * 4 );
	renderer.readRenderTargetPixels( target, 0, 0, size, size, out );
	renderer.setRenderTarget( null );
	camera.aspect = aspect;
	camera.updateProjectionMatrix();
	if ( ! still ) renderer.setAnimationLoop( animate );
	return { size, data: toBase64( out ) };

}

// Point the camera at where the wrinkles are: render the activation (debug mode 3: view-space
// position and sum |a_k|) from 14 directions at low resolution with every region weight 1
// (or `weights`), keep the direction that sees the most active pixels, and frame their
// positions. Returns the number of active pixels seen.
function focusWrinkles( weights ) {

	if ( ! state.wrinkles.length ) return 0;
	const n = state.wrinkles[ 0 ].weights.length;
	const saved = Array.from( state.wrinkles[ 0 ].weights );
	const w = weights || new Array( n ).fill( 1 );
	const box = new THREE.Box3().setFromObject( state.gltf.scene );
	const centre = box.getCenter( new THREE.Vector3() );
	const radius = box.getSize( new THREE.Vector3() ).length() * 0.5;
	const dirs = [];
	for ( const x of [ - 1, 0, 1 ] ) for ( const y of [ - 1, 0, 1 ] ) for ( const z of [ - 1, 0, 1 ] ) {

		const k = Math.abs( x ) + Math.abs( y ) + Math.abs( z );
		if ( k === 1 || k === 3 ) dirs.push( new THREE.Vector3( x, y, z ).normalize() );

	}

	const size = 64;
	const pixels = new Float32Array( size * size * 4 );
	let best = null;
	for ( const d of dirs ) {

		camera.position.copy( centre ).addScaledVector( d, radius * 3 );
		if ( Math.abs( d.y ) > 0.9 ) camera.up.set( 0, 0, - Math.sign( d.y ) );
		else camera.up.set( 0, 1, 0 );
		camera.lookAt( centre );
		camera.near = radius * 0.5;
		camera.far = radius * 6;
		camera.updateMatrixWorld();
		const img = debugPixels( 3, w, size, pixels );
		const pts = [];
		for ( let i = 0; i < size * size; i ++ ) {

			if ( img[ i * 4 + 3 ] > 1e-4 ) pts.push( new THREE.Vector3( img[ i * 4 ], img[ i * 4 + 1 ], img[ i * 4 + 2 ] ).applyMatrix4( camera.matrixWorld ) );

		}

		if ( ! best || pts.length > best.pts.length ) best = { d, pts, up: camera.up.clone() };

	}

	setWeights( saved );
	if ( ! best.pts.length ) {

		frame( state.gltf.scene );
		return 0;

	}

	const focus = new THREE.Box3().setFromPoints( best.pts );
	const c = focus.getCenter( new THREE.Vector3() );
	const r = Math.max( focus.getSize( new THREE.Vector3() ).length() * 0.6, radius * 0.05 );
	const dist = r / Math.tan( THREE.MathUtils.degToRad( camera.fov * 0.5 ) );
	camera.up.copy( best.up );
	camera.position.copy( c ).addScaledVector( best.d, dist );
	camera.near = dist / 50;
	camera.far = dist + radius * 4;
	camera.lookAt( c );
	camera.updateProjectionMatrix();
	controls.target.copy( c );
	controls.update();
	return best.pts.length;

}

// The region weights the animation `clip` gives at each time (the mixer's own evaluation).
function sampleWeights( clipIndex, times ) {

	const clip = state.gltf.animations[ clipIndex ];
	const mixer = new THREE.AnimationMixer( state.gltf.scene );
	const action = mixer.clipAction( clip );
	action.play();
	const out = times.map( ( t ) => {

		mixer.setTime( t );
		return Array.from( state.wrinkles[ 0 ].weights );

	} );
	action.stop();
	mixer.uncacheRoot( state.gltf.scene );
	return out;

}

async function start() {

	const info = await ( await fetch( '/asset.json' ) ).json();
	resize();
	return load( info.gltf );

}

window.wrinklepipe = { ready: start(), load, setWeights, renderDebug, renderDebugSets, renderColor, focusWrinkles, sampleWeights, state, renderer, THREE };
window.wrinklepipe.ready.catch( ( e ) => {

	$( 'status' ).textContent = String( e );
	console.error( e );

} );
