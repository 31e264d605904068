"""What espeak-ng reads badly, written out as said (realtime_core/synthesis/text.py, normalise_for_speech): a table
of a chatbot's answers -> the text espeak-ng is given, and what is left alone because espeak-ng reads it well.
The phonemes each gave before and after: scripts/text_speech_survey.py (session text50)."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ConfigError
from realtime_core.synthesis.text import SentenceChunker, clean_text, normalise_for_speech

REWRITTEN = [
    # URLs: the host alone ("h t t p s colon slash slash docs dot python dot org slash three slash library ...")
    (
        "en",
        "You can find the docs at https://docs.python.org/3/library/re.html.",
        "You can find the docs at docs.python.org.",
    ),
    ("en", "Go to www.github.com/facecast/issues?state=open&sort=new to see them.", "Go to github.com to see them."),
    ("en", "Check http://localhost:8080/api/v1 in your browser.", "Check localhost port 8080 in your browser."),
    ("en", "Read the FAQ at https://example.com/faq#pricing.", "Read the FAQ at example.com."),
    ("en", "See example.com/docs, or <https://example.com>.", "See example.com, or <example.com>."),
    ("en", "Visit http://127.0.0.1:8000/docs now.", "Visit 127 dot 0 dot 0 dot 1 port 8000 now."),
    ("es", "Visita www.ejemplo.es/a?b=c para más.", "Visita ejemplo.es para más."),
    ("es", "Consulta http://localhost:8080/api en tu navegador.", "Consulta localhost puerto 8080 en tu navegador."),
    # dates ("two thousand twenty six dash twelve dash zero seven", "deck seven", "cero siete barra doce barra ...")
    ("en", "The release is scheduled for 2026-12-07.", "The release is scheduled for December 7th, 2026."),
    ("en", "The meeting is on 12/07/2026 at 14:30.", "The meeting is on December 7th, 2026 at 14:30."),
    ("en", "It was due 31/12/2025.", "It was due December 31st, 2025."),  # a field over 12 is the day
    ("en", "It starts Dec 7 at 2:30 pm.", "It starts December 7th at 2:30 pm."),
    ("en", "It starts Dec. 7.", "It starts December 7th."),
    ("en", "The report from Jan 15, 2025 is ready.", "The report from January 15th, 2025 is ready."),
    ("en", "On 7 December 2026 and 3 Dec.", "On the 7th of December 2026 and the 3rd of December."),
    ("es", "La reunión es el 07/12/2026 a las 14:30.", "La reunión es el 7 de diciembre de 2026 a las 14:30."),
    ("es", "La fecha límite es el 2026-12-07.", "La fecha límite es el 7 de diciembre de 2026."),
    ("es", "El 5 dic. 2026 y el 7 dic.", "El 5 de diciembre de 2026 y el 7 de diciembre."),
    # times ("nine zero zero", "nine zero five"; "nueve cero cero", "diez treinta hache")
    ("en", "It's open 9:00-17:00, Mon-Fri.", "It's open 9 o'clock to 17 hundred, Monday to Friday."),
    ("en", "The call is at 9:05 am, not 9:00 AM or 00:00.", "The call is at 9 oh 5 am, not 9 AM or midnight."),
    ("es", "Abre de 9:00 a 17:00.", "Abre de 9 a 17."),
    ("es", "Nos vemos a las 9:05.", "Nos vemos a las 9 y 5."),
    ("es", "La Dra. García te atenderá a las 10:30 h.", "La Dra. García te atenderá a las 10:30 horas."),
    # amounts ("dollar five", "dollar nineteen point nine nine", "three point five zero your", "uno euro")
    (
        "en",
        "That costs $5, or $19.99 with shipping.",
        "That costs 5 dollars, or 19 dollars and 99 cents with shipping.",
    ),
    ("en", "The ticket is 3.50 EUR, about €20.", "The ticket is 3 euros and 50 cents, about 20 euros."),
    (
        "en",
        "Raised $5M, then $2.5 billion; $0.99, £3.50, 5 $.",
        "Raised 5 million dollars, then 2.5 billion dollars; 99 cents, 3 pounds and 50 pence, 5 dollars.",
    ),
    ("es", "Cuesta 3,50 € o 20 EUR.", "Cuesta 3 euros con 50 céntimos o 20 euros."),
    ("es", "El precio es de $5, o 1 € y $5 millones.", "El precio es de 5 dólares, o un euro y 5 millones de dólares."),
    # units ("five k m", "twenty degrees C", "tres ge be")
    ("en", "It's a 5 km run and it's 20°C outside.", "It's a 5 kilometer run and it's 20 degrees Celsius outside."),
    ("en", "You need 3 GB of RAM, 1 h and 2.5 kg.", "You need 3 gigabytes of RAM, 1 hour and 2.5 kilograms."),
    ("es", "Hace 20ºC y caminamos 5 km en 1 h.", "Hace 20 grados Celsius y caminamos 5 kilómetros en una hora."),
    ("es", "Necesitas 3 GB de memoria.", "Necesitas 3 gigabáits de memoria."),
    # versions ("vee two point one point three", "uve dos ...")
    ("en", "Upgrade to v2.1.3 or later.", "Upgrade to version 2.1.3 or later."),
    ("es", "Actualiza a la v2.1.3.", "Actualiza a la versión 2.1.3."),
    # phone numbers in English, digit by digit ("five hundred fifty five ... one hundred twenty three dash four ...")
    ("en", "Call +1 (555) 123-4567 or 555-0199.", "Call plus 1, 5 5 5, 1 2 3, 4 5 6 7 or 5 5 5, 0 1 9 9."),
    # ranges ("ten dash twenty", "five ten": the en dash was dropped)
    (
        "en",
        "Expect 10-20 minutes, pages 5–10, $10-$20.",
        "Expect 10 to 20 minutes, pages 5 to 10, 10 dollars to 20 dollars.",
    ),
    ("es", "Tardará entre 10-20 minutos, de lun-vie.", "Tardará entre 10 y 20 minutos, de lunes a viernes."),
    # after "between" a range is "and", as after "entre" ("between 10 to 20 people" was said)
    ("en", "Between 10-20 people, between $10-$20.", "Between 10 and 20 people, between 10 dollars and 20 dollars."),
    # Spanish ordinals ("uno punto o") and abbreviations ("pe ex", "etk", "ee uu")
    ("es", "Llegó en 1.º lugar y ella en 2.ª posición.", "Llegó en primer lugar y ella en segunda posición."),
    ("es", "El 3.er día, 1.º de la lista.", "El tercer día, primero de la lista."),
    ("es", "Trae frutas, p. ej., manzanas, peras, etc.", "Trae frutas, por ejemplo, manzanas, peras, etcétera."),
    ("es", "EE. UU. vs. España, aprox. 5.", "Estados Unidos contra España, aproximadamente 5."),
    ("en", "Cats vs. dogs, approx. 5.", "Cats versus dogs, approximately 5."),
]

KEPT = [  # espeak-ng reads these well (or they are not what they look like): left as written
    ("en", "Email support@example.com or john.doe@company.co.uk."),  # "support at example dot com"
    ("es", "Escríbenos a soporte@ejemplo.com."),  # "soporte arroba ejemplo punto com"
    ("en", "Visit example.com, ASP.NET or Socket.io."),  # a bare host: "example dot com"
    ("en", "The deadline is December 7th, 2026, at 14:30 or 2:30 pm."),  # "fourteen thirty"
    ("es", "Empieza el 7 de diciembre a las 14:30 y a las 14:05."),  # a 24-hour time: "catorce cero cinco"
    ("en", "Sales grew 12.5% and she finished 1st, he 2nd."),
    ("es", "Las ventas subieron un 12,5%."),
    ("en", "Follow us @facecast and use #MachineLearning. Great job! 🎉"),  # clean_text drops # and emoji
    ("en", "Bring fruit, e.g., apples, pears, etc. Dr. Smith at 9 a.m."),
    ("es", "Llama al +34 912 345 678 o al 912-345-678."),  # Spanish reads phone numbers in groups
    ("en", "Install Node.js, run app.py and open README.md."),  # not domains
    ("en", "5 - 3 = 2, COVID-19, x86-64, GPT-4, 16:9, 25:61, 3/4."),  # a minus, names, a ratio, no time
    ("en", "Python 3.12 in the 90s, March 2026, the file /usr/local/bin/python."),
]


@pytest.mark.parametrize(("language", "text", "said"), REWRITTEN)
def test_what_espeak_reads_badly_is_written_out_as_said(language, text, said):
    assert normalise_for_speech(text, language=language) == said


@pytest.mark.parametrize(("language", "text"), KEPT)
def test_what_espeak_reads_well_is_left_as_written(language, text):
    assert normalise_for_speech(text, language=language) == text


def test_an_ambiguous_numeric_date_follows_the_voice_and_an_unambiguous_one_does_not():
    """'07/12/2026' is July 12 to a US voice and 7 December to a British or Spanish one; '31/12/2025' and
    '12/31/2025' are the same day to all."""
    assert normalise_for_speech("07/12/2026", language="en") == "July 12th, 2026"
    assert normalise_for_speech("07/12/2026", language="en", day_first=True) == "December 7th, 2026"
    assert normalise_for_speech("07/12/2026", language="es") == "7 de diciembre de 2026"
    for day_first in (False, True):
        for text in ("31/12/2025", "12/31/2025", "2025-12-31"):
            assert normalise_for_speech(text, language="en", day_first=day_first) == "December 31st, 2025"
    # not a date: the month or day out of range is left as written
    assert normalise_for_speech("2025-13-01 and 32/01/2025", language="en") == "2025-13-01 and 32/01/2025"


def test_english_ordinal_suffixes_follow_the_number():
    """An independent rule: 1st 2nd 3rd, but 11th 12th 13th, and 21st 22nd 23rd 31st."""
    want = {1: "st", 2: "nd", 3: "rd", 11: "th", 12: "th", 13: "th", 21: "st", 22: "nd", 23: "rd", 31: "st"}
    for day in range(1, 32):
        got = normalise_for_speech(f"May {day}", language="en")
        assert got == f"May {day}{want.get(day, 'th')}"


def test_a_url_leaves_nothing_of_its_path_for_the_cleaning_to_leave_behind():
    """clean_text drops '#' and '_' as markdown: without the normalisation first, '/faq#pricing' and
    '/wiki/Speech_synthesis' left 'faq pricing' and 'Speech synthesis' in the speech after the spelled URL."""
    assert clean_text("See https://en.wikipedia.org/wiki/Speech_synthesis#History now.", language="en") == (
        "See en.wikipedia.org now."
    )
    assert clean_text("See [the docs](https://example.com/docs) now.", language="en") == "See the docs now."
    assert clean_text("See https://example.com/docs now.") == "See https://example.com/docs now."  # no language
    with pytest.raises(ConfigError, match="unsupported language 'fr'"):
        clean_text("Voir https://example.com.", language="fr")


def test_a_month_or_spanish_abbreviation_before_a_number_or_lower_case_word_ends_no_sentence():
    """'It starts Dec. 7 at noon.' was cut after 'Dec.' (two sentences, ~0.45 s of silence between, and 'Dec.'
    alone read 'deck'); the same chunks whatever the chunking."""
    text = "It starts Dec. 7 at noon. Trae frutas, p. ej. manzanas. Viaja a EE. UU. mañana. Then more."
    want = ["It starts Dec. 7 at noon.", "Trae frutas, p. ej. manzanas.", "Viaja a EE. UU. mañana.", "Then more."]
    rng = np.random.default_rng(0)
    for k in range(10):
        c, got = SentenceChunker(), []
        cuts = np.sort(rng.choice(len(text), 6, replace=False)) if k else []
        for piece in np.split(np.array(list(text)), cuts):
            got += c.push("".join(piece))
        assert got + c.flush() == want
