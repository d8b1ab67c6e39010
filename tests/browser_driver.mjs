// Drive Debian's chromium (headless, through npm's playwright-core; never a downloaded browser)
// over a `wrinklepipe view` page: one page load, then a list of calls on window.wrinklepipe.
//   node tests/browser_driver.mjs job.json
// job: { url, playwright (path to playwright-core), chromium, out, calls: [{ fn, args, file }] }
// Each call's result is written to results.json; a result with `data` (base64 float32) is
// written to `file` under `out` instead (split evenly over `files` when the call names
// several). Requests to anything but 127.0.0.1 are refused.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { createRequire } from 'node:module';

const job = JSON.parse( fs.readFileSync( process.argv[ 2 ], 'utf8' ) );
const require = createRequire( import.meta.url );
const { chromium } = require( job.playwright );
const profile = fs.mkdtempSync( path.join( os.tmpdir(), 'wrinklepipe-chromium-' ) );
const log = [];
let context;
try {

	context = await chromium.launchPersistentContext( profile, {
		executablePath: job.chromium,
		headless: true,
		args: [ '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
			'--disable-background-networking', '--disable-component-update', '--disable-sync',
			'--enable-unsafe-swiftshader', '--use-angle=swiftshader' ],
	} );
	const page = context.pages()[ 0 ] || await context.newPage();
	await page.route( '**/*', ( route ) => {

		const host = new URL( route.request().url() ).hostname;
		return host === '127.0.0.1' ? route.continue() : route.abort();

	} );
	page.on( 'console', ( m ) => log.push( `${ m.type() }: ${ m.text() }` ) );
	page.on( 'pageerror', ( e ) => log.push( `pageerror: ${ e.message }` ) );
	await page.goto( job.url );
	const results = [];
	results.push( { fn: 'ready', value: await page.evaluate( () => window.wrinklepipe.ready ) } );
	for ( const call of job.calls ) {

		const t0 = Date.now();
		const value = await page.evaluate( ( [ fn, args ] ) => window.wrinklepipe[ fn ]( ...args ), [ call.fn, call.args ] );
		log.push( `time: ${ call.fn } ${ Date.now() - t0 } ms` );
		if ( value && typeof value.data === 'string' && call.files ) {

			// several images one after another (renderDebugSets): one file each
			const data = Buffer.from( value.data, 'base64' );
			const n = data.length / call.files.length;
			call.files.forEach( ( file, i ) => fs.writeFileSync( path.join( job.out, file ), data.subarray( i * n, ( i + 1 ) * n ) ) );
			results.push( { fn: call.fn, files: call.files, size: value.size } );

		} else if ( value && typeof value.data === 'string' && call.file ) {

			fs.writeFileSync( path.join( job.out, call.file ), Buffer.from( value.data, 'base64' ) );
			results.push( { fn: call.fn, file: call.file, size: value.size } );

		} else {

			results.push( { fn: call.fn, value } );

		}

	}

	fs.writeFileSync( path.join( job.out, 'results.json' ), JSON.stringify( { results, log } ) );

} catch ( e ) {

	fs.writeFileSync( path.join( job.out, 'results.json' ), JSON.stringify( { error: String( e && e.stack || e ), log } ) );
	process.exitCode = 1;

} finally {

	if ( context ) await context.close();
	fs.rmSync( profile, { recursive: true, force: true } );

}
