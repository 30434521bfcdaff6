import { defineConfig } from 'vitest/config';

export default defineConfig({
  // Relative asset URLs: the build works wherever --web-root is mounted.
  base: './',
  build: {
    outDir: 'dist',
    emptyOutDir: true,
    // three.js alone is ~500 kB minified; one chunk is fine for this page.
    chunkSizeWarningLimit: 1024,
    commonjsOptions: {
      // draco3d's loader requires node:fs only when it runs under Node: leave
      // that call as it is instead of bundling an empty stand-in.
      ignore: ['node:fs'],
    },
  },
  worker: { format: 'es' },
  // `FILIGREE_HTTP=host:port npm run dev`: the dev server forwards gRPC-Web
  // to a filigree-server's --http port, so the page needs no server=… and
  // the server no CORS.
  server: process.env.FILIGREE_HTTP
    ? { proxy: { '/filigree.v1.Filigree/': { target: `http://${process.env.FILIGREE_HTTP}` } } }
    : {},
  test: {
    include: ['test/**/*.test.ts'],
    environment: 'node',
  },
});
