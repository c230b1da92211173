// The page's WebSocket to the bridge: the same origin and path as the page (so it works behind a
// reverse proxy under a sub-path), the access token the page was opened with, binary messages
// as ArrayBuffers. It reconnects on its own (after 0.5, 1, 2, 4, 5, 5 ... s; 5 s when the bridge
// said it is full) and keeps reporting its state through onState.
const RETRY_MAX_S = 5;

export class Connection {
  constructor({ token, onText, onBinary, onState }) {
    this.token = token;
    this.onText = onText;
    this.onBinary = onBinary;
    this.onState = onState;
    this.retryS = 0.5;
    this.refusedReason = null;
    this.open();
  }

  url() {
    const u = new URL('ws', window.location.href);
    u.protocol = u.protocol === 'https:' ? 'wss:' : 'ws:';
    u.search = this.token ? `?token=${encodeURIComponent(this.token)}` : '';
    u.hash = '';
    return u.toString();
  }

  open() {
    this.onState('connecting', null);
    const ws = new WebSocket(this.url());
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => {
      this.retryS = 0.5;
      this.refusedReason = null;
      this.onState('open', null);
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data === 'string') {
        const msg = JSON.parse(ev.data);
        if (msg.type === 'refused') this.refusedReason = msg.reason;
        this.onText(msg);
      } else {
        this.onBinary(ev.data);
      }
    };
    ws.onclose = (ev) => {
      const refused = this.refusedReason || (ev.code === 1013 ? ev.reason : null);
      const wait = refused ? RETRY_MAX_S : this.retryS;
      this.retryS = Math.min(this.retryS * 2, RETRY_MAX_S);
      this.onState(refused ? 'refused' : 'closed', refused ? `${refused} (retrying in ${wait} s)`
        : `connection lost (code ${ev.code}); retrying in ${wait} s`);
      setTimeout(() => this.open(), wait * 1000);
    };
  }
}
