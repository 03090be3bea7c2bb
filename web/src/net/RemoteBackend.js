// Placeholder until the server path lands: renders locally.
import { WebGLBackend } from '../render/WebGLBackend.js';
export class RemoteBackend extends WebGLBackend {}
