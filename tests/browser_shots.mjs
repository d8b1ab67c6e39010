// Screenshots of wrinklepipe's pages in Debian's chromium (headless, through npm's
// playwright-core; never a downloaded browser), for tests/test_report_pictures.py.
//   node tests/browser_shots.mjs job.json
// job: { playwright, chromium, out, pages: [{ url, width, height, ready, steps, shot, evaluate }] }
// For each page: load `url` (a file: URL or http://127.0.0.1), wait until the JS expression
// `ready` is true, run each of `steps` (JS statements; one at a time, waiting for `ready` again
// after each), take a screenshot of the viewport into `out/shot`, and store the value of the JS
// expression `evaluate` in results.json. Requests to other hosts are refused.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { createRequire } from 'node:module';

const job = JSON.parse( fs.readFileSync( process.argv[ 2 ], 'utf8' ) );
const require = createRequire( import.meta.url );
const { chromium } = require( job.playwright );
const profile = fs.mkdtempSync( path.join( os.tmpdir(), 'wrinklepipe-shots-' ) );
const log = [];
let context;
try {

	context = await chromium.launchPersistentContext( profile, {
		executablePath: job.chromium,
		headless: true,
		args: [ '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
			'--disable-background-networking', '--disable-component-update', '--disable-sync',
			'--enable-unsafe-swiftshader', '--use-angle=swiftshader', '--force-color-profile=srgb',
			'--allow-file-access-from-files' ],
	} );
	const results = [];
	for ( const p of job.pages ) {

		const page = await context.newPage();
		await page.setViewportSize( { width: p.width || 1000, height: p.height || 800 } );
		await page.route( '**/*', ( route ) => {

			const url = new URL( route.request().url() );
			return url.protocol === 'file:' || url.hostname === '127.0.0.1' ? route.continue() : route.abort();

		} );
		page.on( 'console', ( m ) => log.push( `${ m.type() }: ${ m.text() }` ) );
		page.on( 'pageerror', ( e ) => log.push( `pageerror: ${ e.message }` ) );
		await page.goto( p.url );
		const ready = p.ready || 'document.readyState === "complete"';
		await page.waitForFunction( ready, null, { timeout: 120000 } );
		for ( const step of p.steps || [] ) {

			await page.evaluate( step );
			await page.waitForFunction( ready, null, { timeout: 120000 } );

		}

		// two frames: the last step's changes are on screen
		await page.evaluate( () => new Promise( ( r ) => requestAnimationFrame( () => requestAnimationFrame( r ) ) ) );
		if ( p.shot ) await page.screenshot( { path: path.join( job.out, p.shot ) } );
		const value = p.evaluate ? await page.evaluate( p.evaluate ) : null;
		results.push( { url: p.url, shot: p.shot, value } );
		await page.close();

	}

	fs.writeFileSync( path.join( job.out, 'results.json' ), JSON.stringify( { results, log } ) );

} catch ( e ) {

	fs.writeFileSync( path.join( job.out, 'results.json' ), JSON.stringify( { error: String( e && e.stack || e ), log } ) );
	process.exitCode = 1;

} finally {

	if ( context ) await context.close();
	fs.rmSync( profile, { recursive: true, force: true } );

}
