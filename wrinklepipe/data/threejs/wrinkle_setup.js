// wrinklepipe: how a WRINKLEPIPE_wrinkle_maps material reaches the shader, in JavaScript (the
// twin of wrinklepipe/shading/setup.py; a test compares the two on every mask layout).
//
// The core sums the masks in groups of four (an RGBA mask texture; four single-channel layers
// of an `array` table; under `lr-split` a texture times 1, s and 1 - s) and multiplies each group
// by vec4 weights from one flat array. The slot table says, per region, which floats of that
// array its weight is written to (one per state it drives), so the glue each frame is one
// assignment per slot.

export const ENCODINGS = { pd: 0, diff: 1, full: 2, composite: 3 };
export const POLICIES = { clamp01: 0, signed: 1, additive: 2, renormalize: 3, lerp: 4 };
export const GATHERS = ['channels', 'layers', 'split'];
export const LAYOUTS = { rgb: 0, rg: 1, ag: 2 };
export const MAX_STATES = 16;
export const MAX_WEIGHT_VECTORS = 1023;
export const MAX_MASK_LAYERS = 256;
const CHANNELS = 'rgba';

function floatLiteral( x ) {

	const s = String( Number( x ) );
	return /[.e]/.test( s ) ? s : s + '.0';

}

// `ext`: the material's WRINKLEPIPE_wrinkle_maps object. `options`: baseLayout / stateLayout
// ('rgb', 'rg', 'ag'), stateBits (8, 16, 0 for float), output convention ('opengl').
export function wrinkleSetup( ext, options = {} ) {

	const problems = [];
	const states = ( ext.states || [] ).map( ( s ) => s.name );
	const regions = ext.regions || [];
	const masks = ext.masks || { textures: [], table: [] };
	const nLayers = masks.textures.length;
	const table = masks.table || [];
	const byName = new Map( table.map( ( e ) => [ e.region, e ] ) );
	let split = null;
	const entries = regions.map( ( r ) => {

		const e = byName.get( r.name );
		if ( e === undefined ) {

			problems.push( `region '${ r.name }' has no channel table entry` );
			return { layer: 0, channel: 0, part: 0 };

		}

		if ( 'layer' in e ) return { layer: e.layer, channel: 0, part: 0 };
		let part = 0;
		if ( e.split ) {

			const sp = [ e.split.texture, CHANNELS.indexOf( e.split.channel ) ];
			if ( split !== null && ( split[ 0 ] !== sp[ 0 ] || split[ 1 ] !== sp[ 1 ] ) ) {

				problems.push( 'more than one lr-split channel' );

			}

			split = sp;
			part = e.side === 'left' ? 1 : e.side === 'right' ? 2 : 0;

		}

		return { layer: e.texture, channel: CHANNELS.indexOf( e.channel ), part };

	} );
	const gather = split !== null ? 'split' : ( table.length && table.every( ( e ) => 'layer' in e ) ) ? 'layers' : 'channels';
	const nGroups = gather === 'layers' ? Math.ceil( nLayers / 4 ) : nLayers * ( gather === 'split' ? 3 : 1 );
	const signed = ext.policy === 'signed';
	const lanes = signed ? 1 : states.length;
	const quads = Math.ceil( lanes / 4 );
	const groupChannel = ( e ) => {

		if ( gather === 'layers' ) return [ Math.floor( e.layer / 4 ), e.layer % 4 ];
		if ( gather === 'split' ) return [ 3 * e.layer + e.part, e.channel ];
		return [ e.layer, e.channel ];

	};

	const slots = entries.map( ( e, r ) => {

		const [ g, c ] = groupChannel( e );
		const drives = regions[ r ].states || [];
		const ks = signed ? [ 0 ] : states.map( ( s, k ) => k ).filter( ( k ) => drives.length === 0 || drives.includes( states[ k ] ) );
		return ks.map( ( k ) => ( ( g * quads + ( k >> 2 ) ) * 4 + c ) * 4 + ( k & 3 ) );

	} );
	const used = new Float32Array( nGroups * 4 );
	const lane = entries.map( ( e ) => {

		const [ g, c ] = groupChannel( e );
		used[ g * 4 + c ] = 1;
		return g * 4 + c;

	} );
	const nWeightVectors = nGroups * quads * 4;

	if ( ! ( ext.encoding in ENCODINGS ) ) problems.push( `unknown encoding '${ ext.encoding }'` );
	if ( ! ( ext.policy in POLICIES ) ) problems.push( `unknown policy '${ ext.policy }'` );
	if ( states.length === 0 ) problems.push( 'no wrinkle states' );
	if ( states.length > MAX_STATES ) problems.push( `${ states.length } wrinkle states; shaders take at most ${ MAX_STATES }` );
	if ( signed && states.length !== 2 ) problems.push( `policy 'signed' needs exactly two states, the asset has ${ states.length }` );
	if ( regions.length === 0 ) problems.push( 'no regions' );
	if ( nLayers > MAX_MASK_LAYERS ) problems.push( `${ nLayers } mask textures; shaders take at most ${ MAX_MASK_LAYERS }` );
	if ( nWeightVectors + nGroups > MAX_WEIGHT_VECTORS ) {

		problems.push( `${ regions.length } regions x ${ states.length } states need ${ nWeightVectors + nGroups } weight vectors; shaders take at most ${ MAX_WEIGHT_VECTORS }` );

	}

	// the states that carry a colour map (colorTexture), in order: the colour textures' states
	const colorStates = [];
	ext.states.forEach( ( s, k ) => {

		if ( s.colorTexture ) colorStates.push( k );

	} );
	const [ splitLayer, splitChannel ] = split || [ 0, 0 ];
	const output = options.output || 'opengl';
	const defines = {
		WP_ENCODING: String( ENCODINGS[ ext.encoding ] ),
		WP_POLICY: String( POLICIES[ ext.policy ] ),
		WP_SCALE: floatLiteral( ext.scale === undefined ? 1.0 : ext.scale ),
		WP_NUM_STATES: String( states.length ),
		WP_NUM_LAYERS: String( nLayers ),
		WP_NUM_GROUPS: String( nGroups ),
		WP_QUADS: String( quads ),
		WP_NUM_WEIGHTS: String( nWeightVectors ),
		WP_GATHER: String( GATHERS.indexOf( gather ) ),
		WP_SPLIT_LAYER: String( splitLayer ),
		WP_SPLIT_CHANNEL: String( splitChannel ),
		WP_BASE_LAYOUT: String( LAYOUTS[ options.baseLayout || 'rgb' ] ),
		WP_STATE_LAYOUT: String( LAYOUTS[ options.stateLayout || 'rgb' ] ),
		WP_STATE_BITS: String( options.stateBits === undefined ? 8 : options.stateBits ),
		WP_MAPPING: String( ext.mapping === undefined ? 1 : ext.mapping ),
		WP_FLIP_BASE: String( Number( ( options.convention || 'opengl' ) !== output ) ),
		WP_FLIP_STATES: String( Number( ( options.convention || 'opengl' ) !== output ) ),
	};
	if ( colorStates.length ) {

		// the state of colour map c (a chain of conditionals, as wrinklepipe.shading.template)
		const chain = colorStates.slice( 0, - 1 ).map( ( k, c ) => `(c) == ${ c } ? ${ k } : ` ).join( '' );
		defines.WP_NUM_COLORS = String( colorStates.length );
		defines[ 'WP_COLOR_STATE(c)' ] = `(${ chain }${ colorStates[ colorStates.length - 1 ] })`;

	}

	return {
		states, regions: regions.map( ( r ) => r.name ), gather, split, nLayers, nGroups, quads,
		nWeightVectors, slots, used, lane, defines, problems, colorStates,
	};

}

// Region weights [R] -> the flat weight array (Float32Array of nWeightVectors * 4).
export function weightVectors( setup, regionWeights, out = new Float32Array( setup.nWeightVectors * 4 ) ) {

	out.fill( 0 );
	const slots = setup.slots;
	for ( let r = 0; r < slots.length; r ++ ) {

		const w = regionWeights[ r ];
		const s = slots[ r ];
		for ( let i = 0; i < s.length; i ++ ) out[ s[ i ] ] = w;

	}

	return out;

}

// Region colours colour-blind readers can tell apart: Paul Tol's muted, then light, qualitative
// schemes (SRON/EPS/TN/09-002), sRGB; the same table as wrinklepipe/palette.py (a test keeps
// them equal), so the viewer's overlay matches validation.html's legend.
export const REGION_COLOURS = [
	'#CC6677', '#332288', '#DDCC77', '#117733', '#88CCEE', '#882255', '#44AA99', '#999933', '#AA4499',
	'#77AADD', '#EE8866', '#EEDD88', '#FFAABB', '#99DDFF', '#44BB99', '#BBCC33', '#AAAA00', '#DDDDDD',
];

// The region r's colour, linear RGB (the shader blends in linear light).
export function regionColour( r ) {

	const hex = REGION_COLOURS[ r % REGION_COLOURS.length ];
	return [ 1, 3, 5 ].map( ( i ) => {

		const c = parseInt( hex.slice( i, i + 2 ), 16 ) / 255;
		return c <= 0.04045 ? c / 12.92 : Math.pow( ( c + 0.055 ) / 1.055, 2.4 );

	} );

}

// Each region's colour at its group lane: vec4 per lane.
export function regionColors( setup ) {

	const out = new Float32Array( setup.nGroups * 16 );
	setup.lane.forEach( ( lane, r ) => {

		const c = regionColour( r );
		out.set( [ c[ 0 ], c[ 1 ], c[ 2 ], 1 ], lane * 4 );

	} );
	return out;

}
